"""The lander in MuJoCo: the ``MjSpec`` model builder (:mod:`.model`) and the touchdown
simulation with its metrics and energy ledger (:mod:`.sim`)."""

from chronogym.tasks.lander.mujoco.model import (
    LanderModelInfo,
    build_lander_model,
    build_lander_spec,
)
from chronogym.tasks.lander.mujoco.sim import LEDGER_TERMS, LanderSim, simulate_landing

__all__ = [
    "LEDGER_TERMS",
    "LanderModelInfo",
    "LanderSim",
    "build_lander_model",
    "build_lander_spec",
    "simulate_landing",
]
