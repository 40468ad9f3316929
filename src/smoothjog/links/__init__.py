"""Byte and line transports to a controller; they know nothing of jogging."""
