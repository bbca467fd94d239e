"""Training benchmarks: RL scaling and throughput, time to walk, robustness, SB3."""
