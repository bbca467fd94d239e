"""Deprecated: the Go1's evaluation moved to :mod:`chronogym.tasks.quadruped.evaluation`,
and ``VideoRecorder`` to :mod:`chronogym.video`.

``chronogym.rl.evaluate.NAME`` still works and warns; import from the new home instead. The
public names (``evaluate``, ``VideoRecorder``, ``WalkingCriterion``, ``WalkingEvaluator``) stay
importable from :mod:`chronogym.rl`.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

_EVALUATION = "chronogym.tasks.quadruped.evaluation"

#: Each old name -> the module that holds it now.
_MOVED: dict[str, str] = {
    **dict.fromkeys(
        (
            "Policy",
            "DEFAULT_COMMANDS",
            "EpisodeResult",
            "run_episode",
            "run_episodes_together",
            "evaluate",
            "summarize",
            "format_summary",
            "WalkingCriterion",
            "check_walking",
            "WalkingEvaluator",
        ),
        _EVALUATION,
    ),
    "VideoRecorder": "chronogym.video",
}


def __getattr__(name: str) -> Any:
    module = _MOVED.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"{__name__}.{name} moved to {module}.{name}", DeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(module), name)
