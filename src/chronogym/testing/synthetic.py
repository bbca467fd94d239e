"""SyntheticEnv: a Gymnasium env whose step costs a controlled, drawn wall time and no CPU.

Its step waits for a drawn duration while releasing the CPU (``time.sleep``), as a step
that computes on another core would. On a machine with fewer cores than workers, W such
envs in W workers then measure what the vector env itself costs as W grows (the driver's
work, the transport, the barrier's wait for the slowest worker): what a machine with W
cores would show, minus the compute. ``benchmarks/vector/scaling.py`` and ``chronogym
bench`` use it; users can size their runs with it too.

Registered as ``chronogym/Synthetic-v0``; the id's keyword arguments configure it::

    gymnasium.make("chronogym/Synthetic-v0", step_ms=10, cv=0.5, obs_dim=45)

Durations are constant (``cv=0``) or lognormal with mean ``step_ms`` and coefficient of
variation ``cv``, drawn from the env's own ``np_random``: the same seed gives the same
durations and the same observations. ``draw_duration_ms()`` draws the next one without
waiting (what ``step`` calls before it sleeps).

Observations are float32 vectors of ``obs_dim``: element 0 is the last drawn duration in
ms (at reset, a uniform draw in [0, 1)), the others the step count in the episode. The
info holds ``"payload"``, ``info_floats`` float32s (the step count), if ``info_floats > 0``,
and ``info_scalars`` NumPy float64 scalars ``"info_0"``, ``"info_1"``, ... (the step count), as
Gymnasium's MuJoCo tasks report theirs (Ant-v5: nine), or nothing if both are 0. The
action is a Box in [-1, 1] of ``action_dim`` floats; the reward is
``-sum(action**2)``. Episodes never terminate and truncate after ``max_steps`` steps.

Sleeping accurately: Linux lets a sleep end up to the thread's timer slack (50 µs by
default) late, and a VM adds its wake-up latency; at 0.1 ms per step that is a third more.
With ``precise_sleep=True`` (default) the stepping thread's timer slack is set to 1 µs
(``prctl``, Linux only) and each sleep starts a learned lead earlier, so that the mean
wait matches the drawn durations (the lead is at most 100 µs and half the duration); no CPU
is burned.
"""

from __future__ import annotations

import ctypes
import functools
import math
import sys
import threading
import time
from typing import Any

import gymnasium as gym
import numpy as np

from chronogym.errors import RenderModeError
from chronogym.validation import check_bool, check_int, check_number

ENV_ID = "chronogym/Synthetic-v0"
#: ``prctl`` option that sets the calling thread's timer slack (Linux).
PR_SET_TIMERSLACK = 29
#: Timer slack asked for by ``precise_sleep``, ns.
TIMER_SLACK_NS = 1000
#: How fast the sleep's lead follows the measured lateness, and its bounds (s).
LEAD_GAIN = 0.1
MAX_LEAD_S = 0.0001


@functools.cache
def _prctl() -> Any:
    """libc's ``prctl``, or None where there is none (not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def lognormal_parameters(mean: float, cv: float) -> tuple[float, float]:
    """``(mu, sigma)`` of the lognormal with this mean and coefficient of variation."""
    sigma2 = math.log1p(cv * cv)
    return math.log(mean) - sigma2 / 2, math.sqrt(sigma2)


class SyntheticEnv(gym.Env):
    """A Gymnasium env whose step sleeps for a drawn duration (see the module doc).

    Args:
        step_ms: mean wall time of a step, ms (>= 0; 0: no wait).
        cv: coefficient of variation of the step's duration (>= 0); 0: every step takes
            ``step_ms``; else lognormal with mean ``step_ms``.
        obs_dim: floats in an observation (>= 1).
        info_floats: floats in each step's info array ``"payload"`` (>= 0; 0: none).
        action_dim: floats in an action (>= 1).
        max_steps: steps in an episode before it truncates (>= 1).
        reset_ms: wall time of a reset, ms (>= 0).
        precise_sleep: end sleeps on time (module doc); False: plain ``time.sleep``.
        info_scalars: float64 scalars in each step's info, ``"info_0"`` ... (>= 0; 0: none).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        step_ms: float = 1.0,
        cv: float = 0.0,
        obs_dim: int = 16,
        info_floats: int = 0,
        action_dim: int = 2,
        max_steps: int = 1000,
        reset_ms: float = 0.0,
        precise_sleep: bool = True,
        render_mode: str | None = None,
        info_scalars: int = 0,
    ) -> None:
        if render_mode is not None:  # a TypeError too: SB3's make_vec_env then asks for None
            raise RenderModeError(
                f"render_mode={render_mode!r}: SyntheticEnv does not render; expected None"
            )
        self.render_mode = None
        self._step_ms, self._cv = 0.0, 0.0
        self.step_ms, self.cv = step_ms, cv
        self.obs_dim = check_int("obs_dim", obs_dim, low=1)
        self.info_floats = check_int("info_floats", info_floats, low=0)
        self.info_scalars = check_int("info_scalars", info_scalars, low=0)
        self._info_keys = tuple(f"info_{k}" for k in range(self.info_scalars))
        self.action_dim = check_int("action_dim", action_dim, low=1)
        self.max_steps = check_int("max_steps", max_steps, low=1)
        self.reset_ms = check_number("reset_ms", reset_ms, low=0, expected="milliseconds >= 0")
        self.precise_sleep = check_bool("precise_sleep", precise_sleep)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.obs_dim,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_dim,), np.float32)
        self._t = 0
        self._lead_s = 0.0
        self._slack_thread: int | None = None

    # -- durations ------------------------------------------------------------------------
    @property
    def step_ms(self) -> float:
        """Mean step duration, ms; settable (``vec.set_attr("step_ms", 0.1)``), as is ``cv``."""
        return self._step_ms

    @step_ms.setter
    def step_ms(self, value: float) -> None:
        self._step_ms = check_number("step_ms", value, low=0, expected="milliseconds >= 0")

    @property
    def cv(self) -> float:
        """Coefficient of variation of the step durations (0: constant)."""
        return self._cv

    @cv.setter
    def cv(self, value: float) -> None:
        self._cv = check_number("cv", value, low=0, expected="a coefficient of variation >= 0")

    def draw_duration_ms(self) -> float:
        """The next step's duration, ms, drawn from ``np_random`` (no waiting)."""
        if self._cv == 0 or self._step_ms == 0:
            return self._step_ms
        mu, sigma = lognormal_parameters(self._step_ms, self._cv)
        return float(self.np_random.lognormal(mu, sigma))

    def _wait(self, seconds: float) -> None:
        """Sleep ``seconds``, releasing the CPU (on time if ``precise_sleep``)."""
        if seconds <= 0:
            return
        if not self.precise_sleep:
            time.sleep(seconds)
            return
        self._tighten_timer_slack()
        deadline = time.perf_counter() + seconds
        time.sleep(seconds - min(self._lead_s, seconds / 2))
        late = time.perf_counter() - deadline
        self._lead_s = min(max(self._lead_s + LEAD_GAIN * late, 0.0), MAX_LEAD_S)

    def _tighten_timer_slack(self) -> None:
        """Set this thread's timer slack to :data:`TIMER_SLACK_NS` once (Linux only)."""
        thread = threading.get_ident()
        if self._slack_thread != thread:
            prctl = _prctl()
            if prctl is not None:
                prctl(PR_SET_TIMERSLACK, TIMER_SLACK_NS, 0, 0, 0)
            self._slack_thread = thread

    # -- Gymnasium ----------------------------------------------------------------------------
    def _observation(self, first: float) -> np.ndarray:
        obs = np.full(self.obs_dim, self._t, dtype=np.float32)
        obs[0] = first
        return obs

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {}
        if self.info_floats:
            info["payload"] = np.full(self.info_floats, self._t, dtype=np.float32)
        if self._info_keys:
            value = np.float64(self._t)
            info.update(dict.fromkeys(self._info_keys, value))
        return info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._t = 0
        self._wait(self.reset_ms / 1000)
        return self._observation(float(self.np_random.random())), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        duration_ms = self.draw_duration_ms()
        self._wait(duration_ms / 1000)
        self._t += 1
        reward = -float(np.square(np.asarray(action, dtype=np.float32)).sum())
        obs = self._observation(duration_ms)
        return obs, reward, False, self._t >= self.max_steps, self._info()


def make_synthetic_vector_env(
    num_envs: int,
    *,
    backend: str = "ray",
    vector_options: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> gym.vector.VectorEnv:
    """The vector entry point of ``chronogym/Synthetic-v0``: ``num_envs`` SyntheticEnvs on
    ``backend`` (as :func:`chronogym.registration.make_task_vector_env` does for tasks)."""
    from chronogym.registration import make_vector_env

    factory = functools.partial(SyntheticEnv, **env_kwargs)
    return make_vector_env(factory, num_envs, backend=backend, vector_options=vector_options)
