"""SCM soil benchmarks: its cost per step, and a cross-check against Chrono's SCM."""
