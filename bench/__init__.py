"""smoothjog's benchmarks: jog quality against the physical limits and the reference methods."""
