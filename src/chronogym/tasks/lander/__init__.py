"""Planetary-lander design-optimization case study: the physics building blocks.

A six-legged lunar lander (chassis on the scale of Project Chrono's lander demo) touches
down on rigid terrain or on SCM soil (``Terrain(soil=...)``); each leg's primary strut
crushes an aluminium-honeycomb cartridge.  The design vector ``theta = (f_y, beta,
alpha2)`` -- honeycomb yield force, leg spread angle, primary strut inclination -- is
scored by

    J(theta) = a_max / a_ref + (alpha * (E_abs / E_init - 1))**2

(peak filtered chassis acceleration against the deceleration that just uses the whole
stroke, and how much of the initial energy the absorbers take).

Modules:

* :mod:`~chronogym.tasks.lander.design` -- :class:`LanderDesign`, :data:`DESIGN_BOUNDS`,
  :class:`LanderParams` (every fixed parameter, documented);
* :mod:`~chronogym.tasks.lander.absorber` -- :class:`HoneycombAbsorber`, the crush law;
* :mod:`~chronogym.tasks.lander.model` -- the ``MjSpec`` model builder and its topology,
  :class:`Terrain` (rigid plane, slope, rocks or soil) and :func:`terrain_params`;
* :mod:`~chronogym.tasks.lander.sim` -- :class:`LanderSim` and :func:`simulate_landing`
  (metrics, and the energy ledger whose terms are :data:`LEDGER_TERMS`).

MuJoCo only (and ``chronogym.terrain``, numba, on soil): no Gymnasium, Ray or Optuna
import here.
"""

from chronogym.tasks.lander.absorber import HoneycombAbsorber
from chronogym.tasks.lander.design import (
    DEFAULT_DESIGN,
    DESIGN_BOUNDS,
    DESIGN_NAMES,
    LanderDesign,
    LanderParams,
)
from chronogym.tasks.lander.model import (
    N_LEGS,
    LanderModelInfo,
    Terrain,
    build_lander_model,
    build_lander_spec,
    leg_azimuths,
    terrain_params,
)
from chronogym.tasks.lander.sim import LEDGER_TERMS, LanderSim, simulate_landing

__all__ = [
    "DEFAULT_DESIGN",
    "DESIGN_BOUNDS",
    "DESIGN_NAMES",
    "LEDGER_TERMS",
    "N_LEGS",
    "HoneycombAbsorber",
    "LanderDesign",
    "LanderModelInfo",
    "LanderParams",
    "LanderSim",
    "Terrain",
    "build_lander_model",
    "build_lander_spec",
    "leg_azimuths",
    "simulate_landing",
    "terrain_params",
]
