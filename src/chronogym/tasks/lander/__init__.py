"""Planetary-lander design-optimization case study: the physics building blocks.

A six-legged lunar lander (chassis on the scale of Project Chrono's lander demo) touches
down on rigid terrain or on SCM soil (``Terrain(soil=...)``); each leg's primary strut
crushes an aluminium-honeycomb cartridge.  The design vector ``theta = (f_y, beta,
alpha2)`` -- honeycomb yield force, leg spread angle, primary strut inclination -- is
scored by

    J(theta) = a_max / a_ref + (alpha * (E_abs / E_init - 1))**2

(peak filtered chassis acceleration against the deceleration that just uses the whole
stroke, and how much of the initial energy the absorbers take).

Modules, shared by both engines:

* :mod:`~chronogym.tasks.lander.design` -- :class:`LanderDesign`, :data:`DESIGN_BOUNDS`,
  :class:`LanderParams` (every fixed parameter, documented);
* :mod:`~chronogym.tasks.lander.absorber` -- :class:`HoneycombAbsorber`, the crush law;
* :mod:`~chronogym.tasks.lander.geometry` -- :data:`N_LEGS`, :func:`leg_azimuths` and
  :func:`leg_geometry` (the legs' points and frames every engine's builder uses);
* :mod:`~chronogym.tasks.lander.terrain` -- :class:`Terrain` (rigid plane, slope, rocks or
  soil) and :func:`terrain_params`;
* :mod:`~chronogym.tasks.lander.landing` -- :class:`Landing`, the engine-independent
  history, settling and metrics (:func:`objective`, :func:`filtered_acceleration`).

One sub-package per engine:

* :mod:`~chronogym.tasks.lander.mujoco` -- ``model`` (the ``MjSpec`` model builder and its
  topology) and ``sim`` (:class:`LanderSim` and :func:`simulate_landing`: metrics, and the
  energy ledger whose terms are :data:`LEDGER_TERMS`);
* :mod:`~chronogym.tasks.lander.chrono` -- ``model``, ``struts`` and ``sim``: the same lander
  in Project Chrono (:class:`ChronoLanderSim`, :class:`ChronoSettings`; flat ground, rigid or
  Chrono's SCM soil; needs PyChrono, imported only when a Chrono lander is built).

No Gymnasium, Ray, Optuna or PyChrono import here (``chronogym.terrain``, numba, on soil).
"""

from chronogym.tasks.lander.absorber import HoneycombAbsorber
from chronogym.tasks.lander.chrono.model import ChronoSettings
from chronogym.tasks.lander.chrono.sim import (
    CHRONO_LEDGER_TERMS,
    ChronoLanderSim,
    simulate_chrono_landing,
)
from chronogym.tasks.lander.design import (
    DEFAULT_DESIGN,
    DESIGN_BOUNDS,
    DESIGN_NAMES,
    LanderDesign,
    LanderParams,
)
from chronogym.tasks.lander.geometry import N_LEGS, leg_azimuths, leg_geometry
from chronogym.tasks.lander.landing import Landing, filtered_acceleration, objective
from chronogym.tasks.lander.mujoco.model import (
    LanderModelInfo,
    build_lander_model,
    build_lander_spec,
)
from chronogym.tasks.lander.mujoco.sim import LEDGER_TERMS, LanderSim, simulate_landing
from chronogym.tasks.lander.terrain import Terrain, terrain_params

__all__ = [
    "CHRONO_LEDGER_TERMS",
    "DEFAULT_DESIGN",
    "DESIGN_BOUNDS",
    "DESIGN_NAMES",
    "LEDGER_TERMS",
    "N_LEGS",
    "ChronoLanderSim",
    "ChronoSettings",
    "HoneycombAbsorber",
    "LanderDesign",
    "LanderModelInfo",
    "LanderParams",
    "LanderSim",
    "Landing",
    "Terrain",
    "build_lander_model",
    "build_lander_spec",
    "filtered_acceleration",
    "leg_azimuths",
    "leg_geometry",
    "objective",
    "simulate_chrono_landing",
    "simulate_landing",
    "terrain_params",
]
