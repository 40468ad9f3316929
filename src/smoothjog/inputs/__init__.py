"""Input devices and scripts that produce jog intents; they know nothing of Grbl."""
