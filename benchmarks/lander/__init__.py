"""The lander design study: Optuna trials per second against workers."""
