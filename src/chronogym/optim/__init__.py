"""Parallel Bayesian optimization: Optuna ask/tell with trials evaluated on Ray workers."""

from chronogym.optim.parallel import StudyReport, TrialFailure, run_parallel_study
from chronogym.optim.storage import DEFAULT_STORAGE, open_storage

__all__ = [
    "DEFAULT_STORAGE",
    "StudyReport",
    "TrialFailure",
    "open_storage",
    "run_parallel_study",
]
