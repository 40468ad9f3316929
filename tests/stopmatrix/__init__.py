"""The STOP matrix: every stop source against every kind of motion, on the served simulator."""
