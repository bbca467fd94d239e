"""Small objectives for the optimizer tests (importable by Ray workers)."""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path

from chronogym.optim import TrialFailure


def suggest_x(trial) -> dict[str, float]:
    return {"x": trial.suggest_float("x", 0.0, 1.0)}


@dataclass(frozen=True)
class Quadratic:
    """J = (x - 0.3)^2; fails above ``fail_above``; the worker kills itself once at x >= ``die_at``.

    ``marker`` is a file that records the one self-kill, so the retried trial succeeds.
    """

    fail_above: float = 2.0
    die_at: float = 2.0
    marker: str = ""
    delay: float = 0.0
    always_die: bool = False
    hang_above: float = 2.0

    def __call__(self):
        def evaluate(params):
            x = params["x"]
            time.sleep(self.delay)
            first_time = bool(self.marker) and not Path(self.marker).exists()
            if x >= self.die_at and (self.always_die or first_time):
                if self.marker:
                    Path(self.marker).write_text(str(os.getpid()))
                os.kill(os.getpid(), signal.SIGKILL)
            if x > self.hang_above:
                time.sleep(600)
            if x > self.fail_above:
                raise TrialFailure(f"x={x:.3f} is in the failing region")
            return (x - 0.3) ** 2, {"x_seen": x}

        return evaluate
