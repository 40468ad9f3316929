"""smoothjog: smooth, low-latency, safe jogging for Grbl-family CNC controllers."""

__version__ = "0.1.0"
__all__ = ["__version__"]
