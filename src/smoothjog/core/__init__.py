"""The pure core: grammar, machine model and jog math; no I/O, no asyncio, no clock reads."""
