"""The lander in Project Chrono: the model (:mod:`.model`, built from the MuJoCo model's
mass properties), the struts' force functors (:mod:`.struts`) and the touchdown simulation
(:mod:`.sim`).  Flat rigid ground only.

PyChrono is optional: nothing here imports it at module import; it is imported when a
Chrono lander is built (``chronogym.engines.chrono.import_pychrono``).
"""

from chronogym.tasks.lander.chrono.model import ChronoSettings
from chronogym.tasks.lander.chrono.sim import (
    CHRONO_LEDGER_TERMS,
    ChronoLanderSim,
    simulate_chrono_landing,
)

__all__ = ["CHRONO_LEDGER_TERMS", "ChronoLanderSim", "ChronoSettings", "simulate_chrono_landing"]
