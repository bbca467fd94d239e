"""Chrono against MuJoCo: the same landing in both engines, and sim-to-sim transfer."""
