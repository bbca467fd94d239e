"""The lander on SCM soil: a real drop, its energy ledger, reset, serial vs Ray, the CLI.

Real MuJoCo, real numba soil, real Ray (the session's 2-CPU cluster) and real Optuna
SQLite storage; no mocks.  A soil landing steps at 0.125 ms and takes ~2 s.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import optuna
import pytest

from chronogym.cli import build_parser
from chronogym.optim import open_storage, run_parallel_study
from chronogym.optim.lander import (
    SOIL_PRESET,
    LanderObjective,
    make_terrain,
    suggest_lander_design,
)
from chronogym.tasks.lander import (
    DEFAULT_DESIGN,
    LEDGER_TERMS,
    LanderParams,
    LanderSim,
    Terrain,
    simulate_landing,
)

optuna.logging.set_verbosity(optuna.logging.WARNING)

P = LanderParams()
E_INIT = P.e_init
SOIL = Terrain(soil=SOIL_PRESET)
PRE_STEPS = 3200  # 0.4 s: the whole impact; a multiple of run()'s 40-tick settle check
DESIGNS = [  # default; f_y only (same model, soil reset); new geometry (model and soil rebuilt)
    {"f_y": 4000.0, "beta": math.radians(60.0), "alpha2": math.radians(30.0)},
    {"f_y": 8000.0, "beta": math.radians(60.0), "alpha2": math.radians(30.0)},
    {"f_y": 3000.0, "beta": math.radians(40.0), "alpha2": math.radians(20.0)},
]


@pytest.fixture(scope="module")
def soil_landing() -> tuple[LanderSim, dict, np.ndarray]:
    """The default design dropped on soil: (sim at the end, metrics, soil work per tick)."""
    sim = LanderSim(DEFAULT_DESIGN, terrain=SOIL)
    taken = np.empty(PRE_STEPS)
    for i in range(PRE_STEPS):
        sim.step()
        taken[i] = sim.soil.energy_dissipated
    return sim, sim.run(), taken


def test_soil_landing_sinks_centimetres_and_settles(soil_landing) -> None:
    sim, r, _ = soil_landing
    assert sim.params.timestep == P.soil_timestep
    assert r["settled"] and not r["tipped_over"] and not r["bottomed_out"]
    assert 0.05 < r["max_sinkage"] < 0.3  # measured 18 cm: visible, and less than a stroke
    sinkage = sim.soil.sinkage
    assert sinkage.max() == pytest.approx(r["max_sinkage"], abs=0.01)  # the pads rest in it
    assert sim.data.ncon == 0  # the rigid plane no longer holds the pads (they are below it)
    assert 0.0 < r["max_stroke"] < P.max_stroke
    assert r["J"] == pytest.approx(
        r["a_max"] / r["a_ref"] + (P.energy_weight * (r["E_abs"] / r["E_init"] - 1.0)) ** 2
    )


def test_soil_energy_ledger_balances_with_the_soil_term(soil_landing) -> None:
    _, r, _ = soil_landing
    e = r["energy"]
    terms = sum(e[k] for k in LEDGER_TERMS)
    assert e["E_in"] == pytest.approx(terms + e["KE"] + e["residual"], rel=1e-12)
    assert abs(e["residual"]) <= 0.01 * E_INIT and e["residual_max"] <= 0.01 * E_INIT
    # the soil takes a large share, booked both ways: at the bodies and by the soil itself
    assert 0.3 * E_INIT < e["soil"] < e["E_in"]
    assert e["soil"] == pytest.approx(
        e["soil_dissipated"] + e["soil_elastic"] + e["soil_coupling"], rel=1e-12
    )
    assert abs(e["soil_coupling"]) <= 0.005 * E_INIT
    assert r["E_soil"] == pytest.approx(e["soil_dissipated"] + e["soil_elastic"])
    assert 0.0 <= e["soil_elastic"] < 0.001 * E_INIT
    # no MuJoCo contact at all: the soil holds the lander
    assert e["friction"] == 0.0 and e["contact_normal"] == 0.0
    assert 0.3 * E_INIT < r["E_abs"] < e["E_in"] - e["soil"]


def test_soil_only_dissipates(soil_landing) -> None:
    sim, _, taken = soil_landing
    assert taken.min() >= 0.0 and sim.soil.energy_dissipated > 0.3 * E_INIT
    # per tick it gives back at most a little elastic energy (measured 0.14 J)
    assert np.diff(taken).min() > -1.0


def test_rigid_landing_has_no_soil_terms() -> None:
    r = simulate_landing(DEFAULT_DESIGN)
    e = r["energy"]
    assert r["E_soil"] == 0.0 and r["max_sinkage"] == 0.0
    assert e["soil"] == e["soil_dissipated"] == e["soil_elastic"] == e["soil_coupling"] == 0.0


def assert_same_metrics(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_rerun_after_reset_is_bit_identical() -> None:
    sim = LanderSim(DEFAULT_DESIGN, terrain=SOIL)
    soil, model = sim.soil, sim.model
    first = sim.run()
    sim.reset(DEFAULT_DESIGN.replace(f_y=8000.0))  # another landing ruts the soil ...
    for _ in range(1600):
        sim.step()
    assert sim.soil.plastic_sinkage.max() > 0.01
    sim.reset(DEFAULT_DESIGN)  # ... and reset restores it, in place
    assert sim.soil is soil and sim.model is model
    assert sim.soil.plastic_sinkage.max() == 0.0 and sim.soil.energy_dissipated == 0.0
    assert_same_metrics(first, sim.run())


def enqueued_study(tmp_path, name: str) -> optuna.Study:
    storage = open_storage(f"sqlite:///{tmp_path}/{name}.db")
    study = optuna.create_study(storage=storage, study_name=name)
    for params in DESIGNS:
        study.enqueue_trial(params)
    return study


def test_serial_and_ray_evaluate_soil_designs_identically(ray_cluster, tmp_path) -> None:
    results = {}
    for backend, workers in (("serial", 1), ("ray", 2)):
        study = enqueued_study(tmp_path, backend)
        report = run_parallel_study(
            study,
            suggest_lander_design,
            LanderObjective(terrain="soil"),
            len(DESIGNS),
            workers=workers,
            backend=backend,
            progress=False,
        )
        assert report.completed == len(DESIGNS) and report.failed == 0
        results[backend] = sorted((t.number, t.params, t.value, t.user_attrs) for t in study.trials)
    assert results["serial"] == results["ray"]
    for _, params, _, attrs in results["serial"]:
        assert params in DESIGNS and attrs["max_sinkage"] > 0.01 and attrs["E_soil"] > 0.0


def test_cli_optimize_on_soil_records_trials(tmp_path) -> None:
    url = f"sqlite:///{tmp_path}/cli.db"
    cmd = [sys.executable, "-m", "chronogym.cli", "optimize", "lander", "--terrain", "soil"]
    cmd += ["--trials", "2", "--workers", "1", "--backend", "serial", "--storage", url]
    env = {**os.environ, "RAY_ADDRESS": ""}
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "soil terrain" in result.stdout and "best trial" in result.stdout
    study = optuna.load_study(study_name="lander-soil", storage=url)
    assert study.user_attrs["terrain"] == "soil"
    done = [t for t in study.trials if t.state.name == "COMPLETE"]
    assert len(done) == 2 and all(t.user_attrs["max_sinkage"] > 0.0 for t in done)


def test_bad_terrains_and_soils_are_rejected(capsys) -> None:
    with pytest.raises(ValueError, match=r"terrain='lava': expected one of \['rigid', 'rough'"):
        LanderObjective(terrain="lava")
    with pytest.raises(ValueError, match="terrain='lava'.*'soil'"):
        make_terrain("lava")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["optimize", "lander", "--terrain", "lava"])
    assert "invalid choice: 'lava'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="soil preset 'clay': expected one of"):
        Terrain(soil="clay")
    with pytest.raises(ValueError, match="soil=3: expected None, a soil preset name"):
        Terrain(soil=3)
    with pytest.raises(ValueError, match="expected slope=0"):
        Terrain(soil="mars", slope=0.1)
    with pytest.raises(ValueError, match="soil_resolution=1.0: expected at most"):
        Terrain(soil="mars", soil_resolution=1.0)
    with pytest.raises(ValueError, match="soil_extent=4.0: a pad reaches"):
        LanderSim(DEFAULT_DESIGN, terrain=Terrain(soil="mars", soil_extent=4.0))
