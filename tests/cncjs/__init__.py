"""Tests against a real CNCjs 1.11.5 (tools/cncjs) in front of the smoothjog simulator."""
