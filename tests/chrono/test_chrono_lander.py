"""The lander in Project Chrono: model, energy balance, metrics against MuJoCo, the study.

Tests taking the ``chrono`` fixture need PyChrono and are skipped without it (conftest.py).
A Chrono landing is 5-18x dearer than MuJoCo's (3 s for the default design on a loaded
2-core machine, 4000 steps of 0.25 ms), so the checks of the model share one landing cut at
``SHORT`` s (the crush is over by 0.2 s) and only the objective and the study run full
landings.  The last tests run everywhere: they hide PyChrono.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys

import numpy as np
import optuna
import pytest

from chronogym.engines.mujoco import gl_unavailable
from chronogym.optim import open_storage, run_parallel_study
from chronogym.optim.lander import LanderObjective, suggest_lander_design
from chronogym.tasks.lander import DEFAULT_DESIGN, LanderParams, LanderSim, Terrain

SHORT = 0.35  # s: touchdown, crush and the rebound of the elastic line
P_SHORT = dataclasses.replace(LanderParams(), max_time=SHORT)


@pytest.fixture(scope="module")
def landing(chrono):
    """(Chrono sim, its metrics, MuJoCo's metrics): the default design, first SHORT s."""
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    sim = ChronoLanderSim(DEFAULT_DESIGN, P_SHORT)
    return sim, sim.run(), LanderSim(DEFAULT_DESIGN, P_SHORT).run()


def test_same_25_bodies_joints_and_masses_as_mujoco(chrono):
    from chronogym.engines.chrono import system_bodies
    from chronogym.tasks.lander.chrono.model import BODY_NAMES, build_chrono_lander

    p = LanderParams()
    model = build_chrono_lander(DEFAULT_DESIGN, p)
    bodies = system_bodies(model.system)
    assert len(bodies) == 26 and len(model.bodies) == 25  # + the fixed ground
    assert [b.GetName() for b in model.bodies] == list(BODY_NAMES)
    assert sum(b.GetMass() for b in model.bodies) == pytest.approx(p.total_mass)
    assert len(model.system.GetLinks()) == 36
    kinds = [type(item).__name__ for item in model.keep_alive]  # links as built, material
    expected = {
        "ChLinkLockRevolute": 6,
        "ChLinkLockPrismatic": 6,
        "ChLinkLockSpherical": 18,
        "ChLinkTSDA": 6,
        "ChContactMaterialSMC": 1,
    }
    assert {k: kinds.count(k) for k in expected} == expected and len(kinds) == 37
    mj = LanderSim(DEFAULT_DESIGN).model
    for body, name in zip(model.bodies, BODY_NAMES, strict=True):
        # MuJoCo's ball-joint armature (0.01 kg m^2) is added to the bodies the balls move
        armature = 0.01 if name.startswith(("pad", "secondary")) else 0.0
        np.testing.assert_allclose(
            chrono_inertia(body), mj.body_inertia[mj.body(name).id] + armature, rtol=1e-12
        )
    # zero stroke at the touchdown pose
    np.testing.assert_allclose([s.GetLength() for s in model.struts], p.primary_length)


def chrono_inertia(body) -> list[float]:
    v = body.GetInertiaXX()
    return [v.x, v.y, v.z]


def test_default_landing_metrics_are_sane_and_close_to_mujoco(landing):
    sim, m, mj = landing
    p = sim.params
    assert not sim.diverged() and m["t_touchdown"] is not None
    for key in ("J", "a_max", "E_abs", "max_stroke"):
        assert math.isfinite(m[key]) and m[key] > 0
    assert p.timestep == 0.00025 and m["t_end"] == pytest.approx(SHORT)
    # a full landing: a_max -1.8 %, E_abs +0.5 % (benchmarks/results/cross_engine.json)
    assert m["a_max"] == pytest.approx(mj["a_max"], rel=0.1)
    assert m["E_abs"] == pytest.approx(mj["E_abs"], rel=0.1)
    assert m["max_stroke"] == pytest.approx(mj["max_stroke"], rel=0.1)
    assert 0.1 < m["max_stroke"] < p.max_stroke and not m["bottomed_out"]
    assert m["max_tilt"] < 0.01 and not m["tipped_over"]
    assert m["E_soil"] == 0.0 and m["max_sinkage"] == 0.0
    # the six legs share the load of an upright, vertical touchdown
    assert np.ptp(m["max_stroke_legs"]) < 0.01


def test_energy_balance_closes(landing):
    _, m, _ = landing
    e = m["energy"]
    assert e["E_in"] == pytest.approx(e["KE_0"] + e["PE_released"])
    taken = e["absorbers"] + e["joint_limits"] + e["KE"] + e["rest"]
    assert e["E_in"] == pytest.approx(taken, abs=1e-6)
    # rest: what contacts and joints took, never energy made; booked as contact work, what
    # is left (the potential energy's half-tick offset, the integrator) is about -2 J
    assert e["rest"] > 0.2 * e["E_init"]  # the pads slide: friction takes ~30 %
    assert e["rest"] == pytest.approx(e["contact"] + e["residual"], abs=1e-6)
    assert abs(e["residual"]) < 0.002 * e["E_init"]
    assert e["absorbers_dissipated"] == m["E_abs"]
    assert abs(e["absorbers_coupling"]) < 0.005 * e["E_init"]
    assert e["KE_0"] == pytest.approx(e["E_init"], rel=1e-9)


def test_absorber_law_advances_once_per_tick_and_its_force_is_applied(chrono):
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    sim = ChronoLanderSim(DEFAULT_DESIGN, dataclasses.replace(P_SHORT, max_time=0.05))
    calls = []
    update = sim.absorber.update
    sim.absorber.update = lambda *a: calls.append(1) or update(*a)
    struts = sim.model.strut_forces
    before = [f.calls for f in struts.functors]
    for _ in range(40):  # through the touchdown (~5 ms) into the crush
        sim.step()
        forces = [s.GetForce() for s in sim.model.struts]
        assert not struts.state.any()  # no stop engaged: the struts apply the honeycomb
        np.testing.assert_array_equal(forces, struts.honeycomb)
        np.testing.assert_array_equal(forces, sim.absorber.last_force)
    assert len(calls) == 40
    # Chrono evaluates each functor twice a tick (ForceUpdate at the step start, then the
    # end-of-step update); the law itself ran once
    assert [f.calls - b for f, b in zip(struts.functors, before, strict=True)] == [80] * 6
    assert sim.absorber.last_force.max() > 0  # the struts are loaded


def test_a_design_that_bottoms_out_lands_on_critically_damped_stops(chrono):
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    softest = DEFAULT_DESIGN.replace(f_y=1_000.0)  # bottoms out at 0.13 s
    sim = ChronoLanderSim(softest, dataclasses.replace(P_SHORT, max_time=0.16))
    engaged = np.zeros(6, dtype=bool)
    while sim.time < 0.16:
        sim.step()
        engaged |= sim.model.strut_forces.state == 1
    m, e = sim.metrics(), sim.energy_ledger()
    upper = sim.params.max_stroke + sim.params.stop_margin
    assert engaged.all() and m["bottomed_out"]
    assert upper < m["max_stroke"] < upper + 0.003  # about 1 mm past the stop
    assert e["joint_limits"] > 50.0  # the stops' dampers take work
    assert abs(e["residual"]) < 0.002 * e["E_init"] and e["rest"] > 0


def test_landing_is_deterministic_and_reset_restores_it(chrono):
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    params = dataclasses.replace(P_SHORT, max_time=0.06)
    sim = ChronoLanderSim(DEFAULT_DESIGN, params)
    first = sim.run()
    sim.reset(DEFAULT_DESIGN.replace(f_y=8_000.0))
    stiffer = sim.run()
    sim.reset(DEFAULT_DESIGN)
    again = sim.run()
    assert stiffer["a_max"] > first["a_max"]
    for key in ("a_max", "E_abs", "max_stroke", "J"):
        assert again[key] == first[key]
    np.testing.assert_array_equal(again["E_abs_legs"], first["E_abs_legs"])


def test_chrono_objective_evaluates_a_design(chrono):
    evaluator = LanderObjective(engine="chrono")()
    value, attrs = evaluator({"f_y": 6_000.0, "beta": 1.0, "alpha2": 0.3})
    assert math.isfinite(value) and attrs["settled"] and not attrs["bottomed_out"]
    assert {"a_max", "E_abs", "E_init", "max_stroke"} <= set(attrs)
    assert type(evaluator.sim).__name__ == "ChronoLanderSim"


def test_chrono_study_on_ray_completes_trials(chrono, ray_cluster, tmp_path):
    storage = open_storage(f"sqlite:///{tmp_path}/study.db")
    sampler = optuna.samplers.TPESampler(seed=0, n_startup_trials=2)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(storage=storage, study_name="chrono", sampler=sampler)
    report = run_parallel_study(
        study, suggest_lander_design, LanderObjective(engine="chrono"), 2, workers=2, progress=False
    )
    assert report.completed == 2 and report.failed == 0
    assert all(math.isfinite(t.value) for t in study.trials)
    assert {"a_max", "E_abs", "max_stroke"} <= set(report.best_attrs)


# --- everywhere: no PyChrono needed ----------------------------------------------------------


def test_stops_engage_beyond_a_stop_only_when_they_push_back():
    from chronogym.tasks.lander.chrono.struts import stop_coefficients, stop_engagement

    k, c = stop_coefficients(LanderParams())
    assert k == pytest.approx(2090 / 6 / 0.004**2) and c == pytest.approx(2 * 2090 / 6 / 0.004)
    stroke = np.array([0.0, -1e-12, -0.001, -0.001, 0.15, 0.3201, 0.3201, 0.33])
    rate = np.array([0.0, -1.0, -0.1, 5.0, 1.0, 0.1, -1.0, -1.0])
    np.testing.assert_array_equal(
        stop_engagement(stroke, rate, 0.32, k, c), [0, 0, -1, 0, 0, 1, 0, 1]
    )


def test_chrono_lander_refuses_other_terrains_naming_what_it_supports():
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    for terrain in (Terrain(slope=0.1), Terrain(n_rocks=3)):
        with pytest.raises(ValueError, match=r"supports flat ground, rigid or SCM soil"):
            ChronoLanderSim(terrain=terrain)
    with pytest.raises(
        ValueError,
        match=r"engine='chrono' supports terrain in \['rigid', 'scm'\]; got "
        r"terrain='soil' \(use engine='mujoco' for it\)",
    ):
        LanderObjective(terrain="soil", engine="chrono")
    with pytest.raises(ValueError, match=r"engine='mujoco' supports .*got terrain='scm' \(use "):
        LanderObjective(terrain="scm", engine="mujoco")
    with pytest.raises(ValueError, match=r"engine='bullet': expected one of"):
        LanderObjective(engine="bullet")


NO_PYCHRONO_CLI = """
import sys
sys.modules["pychrono"] = None  # as if PyChrono were not installed
from chronogym.cli import main
try:
    main(["optimize", "lander", "--engine", "chrono", "--trials", "1", "--storage", sys.argv[1]])
except SystemExit as exc:
    print("EXIT:", exc)
else:
    raise SystemExit("optimize --engine chrono ran without pychrono")
ray = sys.modules.get("ray")
print("RAY STARTED" if ray is not None and ray.is_initialized() else "NO RAY")
"""

IMPORTS_ONLY = """
import sys
import chronogym, chronogym.cli, chronogym.optim.lander, chronogym.tasks.lander
import chronogym.tasks.lander.chrono.sim
from chronogym.optim.lander import LanderObjective
LanderObjective()  # the MuJoCo objective
print("pychrono imported" if "pychrono" in sys.modules else "pychrono not imported")
"""


def test_engine_chrono_without_pychrono_is_one_clear_error_before_ray(tmp_path):
    db = tmp_path / "study.db"
    result = subprocess.run(
        [sys.executable, "-c", NO_PYCHRONO_CLI, f"sqlite:///{db}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "EXIT: chronogym optimize lander: engine='chrono'" in out
    assert "pychrono" in out and "conda install projectchrono::pychrono -c conda-forge" in out
    assert "NO RAY" in out and not db.exists()  # stopped before the storage and the workers


def test_cli_refuses_to_mix_engines_in_one_study(tmp_path):
    from chronogym.cli import main

    url = f"sqlite:///{tmp_path}/study.db"
    optuna.create_study(storage=open_storage(url), study_name="s").set_user_attr("engine", "chrono")
    with pytest.raises(SystemExit, match=r"'s' holds chrono trials; --engine mujoco needs another"):
        main(["optimize", "lander", "--storage", url, "--study", "s", "--trials", "1"])


def test_importing_chronogym_never_imports_pychrono():
    result = subprocess.run(
        [sys.executable, "-c", IMPORTS_ONLY], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert "pychrono not imported" in result.stdout


@pytest.mark.skipif(
    gl_unavailable() is not None,
    reason="no offscreen OpenGL (EGL or OSMesa)",
)
def test_chrono_lander_is_drawn_with_the_mujoco_model_of_its_design(chrono):
    from chronogym.tasks.lander import LanderSim
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    chrono_sim, mujoco_sim = ChronoLanderSim(), LanderSim()
    start = chrono_sim.render()
    assert start.shape == (360, 480, 3) and start.std() > 5.0
    # the same touchdown pose in both engines: the same picture
    assert np.abs(start.astype(int) - mujoco_sim.render().astype(int)).mean() < 0.5
    for _ in range(800):  # 0.2 s: the lander moves down and its legs compress
        chrono_sim.step()
    assert np.abs(chrono_sim.render().astype(int) - start.astype(int)).mean() > 0.5
