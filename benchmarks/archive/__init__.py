"""Archived one-off probes: each answered one question or set one constant (README.md)."""
