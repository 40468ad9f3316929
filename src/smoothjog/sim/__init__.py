"""The faithful Grbl jog simulator: smoothjog's embedded default machine."""
