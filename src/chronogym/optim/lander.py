"""The lander design study: search space, terrains, engines and the per-worker evaluator."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from chronogym.engines.chrono import import_pychrono
from chronogym.engines.chrono_scm import import_chrono_vehicle
from chronogym.optim.parallel import TrialFailure

LANDER_METRICS = (
    "a_max",
    "a_ref",
    "E_abs",
    "E_init",
    "max_stroke",
    "E_soil",
    "max_sinkage",
    "bottomed_out",
    "tipped_over",
    "settled",
    "max_tilt",
    "t_end",
)


#: Soil of the ``soil`` terrain: Chrono's ``"mars"`` preset, whose Bekker-Wong and
#: Mohr-Coulomb values (Kc 1.4 kPa/m^(n-1), Kphi 820 kPa/m^n, n 1, c 170 Pa, phi 35 deg) are
#: the classic lunar-regolith ones.  Default design: the pads sink 18 cm (plastic ruts) and the
#: soil takes 4324 J of the 7568 J released; ``"lete_sand"`` would be nearly rigid (1.1 cm).
SOIL_PRESET = "mars"

TERRAINS = ("rigid", "rough", "soil", "scm")

#: Physics engines of the lander: MuJoCo (``LanderSim``) and Project Chrono
#: (``ChronoLanderSim``; needs PyChrono).
ENGINES = ("mujoco", "chrono")
#: Terrains per engine: ``soil`` is chronogym's SCM under MuJoCo bodies, ``scm`` Chrono's own
#: ``SCMTerrain`` (PyChrono's vehicle module), both on :data:`SOIL_PRESET`.
ENGINE_TERRAINS: dict[str, tuple[str, ...]] = {
    "mujoco": ("rigid", "rough", "soil"),
    "chrono": ("rigid", "scm"),
}


def check_engine(engine: str, terrain: str) -> None:
    """Raise before any worker starts if ``engine`` cannot run on ``terrain`` here.

    ``chrono`` needs an importable PyChrono, with its vehicle module for ``scm`` (imported
    here, in the driver, so a missing install is one clear error instead of a failed trial
    per worker).
    """
    if engine not in ENGINES:
        raise ValueError(f"engine={engine!r}: expected one of {list(ENGINES)}")
    if terrain not in ENGINE_TERRAINS[engine]:
        other = next(e for e, ts in ENGINE_TERRAINS.items() if terrain in ts)
        raise ValueError(
            f"engine={engine!r} supports terrain in {list(ENGINE_TERRAINS[engine])}; got "
            f"terrain={terrain!r} (use engine={other!r} for it)"
        )
    if engine != "chrono":
        return
    try:
        import_pychrono()
        if terrain == "scm":
            import_chrono_vehicle()
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(f"engine='chrono': {exc}", name=exc.name) from exc


def make_terrain(name: str) -> Any:
    """Terrain preset by name: ``rigid`` (flat), ``rough`` (8 deg slope, 12 rocks), ``soil`` or
    ``scm`` (flat SCM soil, :data:`SOIL_PRESET`, in MuJoCo or in Chrono; the lander then steps
    at ``soil_timestep``)."""
    from chronogym.tasks.lander import Terrain

    presets = {
        "rigid": lambda: Terrain(),
        "rough": lambda: Terrain(slope=math.radians(8.0), n_rocks=12),
        "soil": lambda: Terrain(soil=SOIL_PRESET),
        "scm": lambda: Terrain(soil=SOIL_PRESET),
    }
    if name not in presets:
        raise ValueError(f"terrain={name!r}: expected one of {list(TERRAINS)}")
    return presets[name]()


def suggest_lander_design(trial: Any) -> dict[str, float]:
    """The paper's priors: f_y log-uniform; beta and alpha2 uniform on DESIGN_BOUNDS."""
    from chronogym.tasks.lander import DESIGN_BOUNDS

    return {
        "f_y": trial.suggest_float("f_y", *DESIGN_BOUNDS["f_y"], log=True),
        "beta": trial.suggest_float("beta", *DESIGN_BOUNDS["beta"]),
        "alpha2": trial.suggest_float("alpha2", *DESIGN_BOUNDS["alpha2"]),
    }


def _simulation_class(engine: str) -> type:
    """``LanderSim`` (MuJoCo) or ``ChronoLanderSim`` (imported only when asked for)."""
    if engine == "chrono":
        from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

        return ChronoLanderSim
    from chronogym.tasks.lander import LanderSim

    return LanderSim


class LanderEvaluator:
    """Evaluates designs in one worker, keeping its simulation between trials.

    MuJoCo: a new ``f_y`` reuses the compiled model; a new geometry rebuilds it
    (``LanderSim.reset``). Chrono rebuilds its system at every reset. A diverged
    simulation is a :class:`TrialFailure`.
    """

    def __init__(self, terrain: str, seed: int, engine: str = "mujoco") -> None:
        self.terrain = make_terrain(terrain)
        self.seed = seed
        self.engine = engine
        self.sim: Any = None

    def __call__(self, params: dict[str, Any]) -> tuple[float, dict[str, Any]]:
        from chronogym.tasks.lander import LanderDesign

        design = LanderDesign(**params)
        if self.sim is None:
            sim_class = _simulation_class(self.engine)
            self.sim = sim_class(design, terrain=self.terrain, seed=self.seed)
        else:
            self.sim.reset(design)
        metrics = self.sim.run()
        if self.sim.diverged() or not math.isfinite(metrics["J"]):
            raise TrialFailure(f"the simulation diverged (J={metrics['J']!r})")
        attrs = {key: _plain(metrics[key]) for key in LANDER_METRICS if key in metrics}
        return float(metrics["J"]), attrs


@dataclass(frozen=True)
class LanderObjective:
    """Picklable factory of :class:`LanderEvaluator`, sent to each worker.

    ``engine="chrono"`` evaluates the designs in Project Chrono (``rigid`` or ``scm``); the
    checks of :func:`check_engine` run here, in the driver, before any worker starts.
    """

    terrain: str = "rigid"
    seed: int = 0
    engine: str = "mujoco"

    def __post_init__(self) -> None:
        if self.terrain not in TERRAINS:
            raise ValueError(f"terrain={self.terrain!r}: expected one of {list(TERRAINS)}")
        check_engine(self.engine, self.terrain)

    def __call__(self) -> LanderEvaluator:
        return LanderEvaluator(self.terrain, self.seed, self.engine)


def describe_design(params: dict[str, float]) -> str:
    """``f_y = 3.52 kN, beta = 61.0 deg, alpha2 = 21.4 deg``."""
    return (
        f"f_y = {params['f_y'] / 1000:.3g} kN, beta = {math.degrees(params['beta']):.1f} deg, "
        f"alpha2 = {math.degrees(params['alpha2']):.1f} deg"
    )


def _plain(value: Any) -> Any:
    """JSON-friendly scalar for Optuna user attributes."""
    if isinstance(value, bool) or value is None:
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)
