"""Lander case study: design validation, honeycomb law, MuJoCo model and touchdowns.

Real MuJoCo, no mocks.  The landings are the slow part (~0.2-0.5 s each); they are
shared through module-scoped fixtures.
"""

from __future__ import annotations

import itertools
import math

import mujoco
import numpy as np
import pytest

from chronogym.tasks.lander import (
    DEFAULT_DESIGN,
    DESIGN_BOUNDS,
    HoneycombAbsorber,
    LanderDesign,
    LanderParams,
    LanderSim,
    Terrain,
    build_lander_model,
    leg_azimuths,
    simulate_landing,
)

F_Y = 4_000.0
S_MAX = 0.3
DELTA_E = 0.003  # elastic stroke


def make_absorber(n: int = 1, damping: float = 0.0) -> HoneycombAbsorber:
    return HoneycombAbsorber(
        n,
        f_y=F_Y,
        max_stroke=S_MAX,
        elastic_stroke=DELTA_E,
        densification_onset=0.8,
        densification_ratio=5.0,
        damping=damping,
    )


def drive(ab: HoneycombAbsorber, start: float, stop: float, n: int = 400) -> np.ndarray:
    """Quasi-static stroke ramp (zero stroke rate); returns the forces along it."""
    return np.array([ab.update(s)[0] for s in np.linspace(start, stop, n)])


# --- design ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"f_y": -5.0}, "f_y"),
        ({"f_y": 1e6}, "f_y"),
        ({"f_y": float("nan")}, "f_y"),
        ({"beta": math.radians(5.0)}, "beta"),
        ({"beta": math.radians(150.0)}, "beta"),
        ({"alpha2": 0.0}, "alpha2"),
        ({"alpha2": math.pi / 2}, "alpha2"),
        ({"alpha2": "steep"}, "alpha2"),
    ],
)
def test_bad_design_raises_naming_value_and_range(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name) as info:
        LanderDesign(**kwargs)
    value = next(iter(kwargs.values()))
    if isinstance(value, float) and math.isfinite(value):
        assert repr(value) in str(info.value) or f"{value:.6g}" in str(info.value)
        low, high = DESIGN_BOUNDS[name]
        assert f"{low:.6g}" in str(info.value) and f"{high:.6g}" in str(info.value)


def test_design_bounds_and_round_trip() -> None:
    lo, hi = DESIGN_BOUNDS["alpha2"]
    assert 0.0 < lo < DEFAULT_DESIGN.alpha2 < hi < math.pi / 2
    for name, (low, high) in DESIGN_BOUNDS.items():
        LanderDesign(**{name: low})  # bounds are inclusive
        LanderDesign(**{name: high})
    d = LanderDesign.from_degrees(6000.0, 45.0, 25.0)
    assert LanderDesign.from_array(d.to_array()) == d
    with pytest.raises(ValueError, match="beta"):
        d.replace(beta=4.0)


def test_params_energy_and_reference() -> None:
    p = LanderParams()
    assert p.gravity == pytest.approx(1.62)
    v = p.touchdown_speed
    assert v == pytest.approx(math.sqrt(2 * 1.62 * 2.0))
    assert p.e_init == pytest.approx(0.5 * p.total_mass * v**2)  # M g h = M v^2 / 2
    assert p.a_ref == pytest.approx(v**2 / (2 * p.max_stroke))
    with pytest.raises(ValueError, match="timestep"):
        LanderParams(timestep=0.0)


# --- honeycomb law ----------------------------------------------------------------------


def test_absorber_elastic_rise_then_plateau() -> None:
    ab = make_absorber()
    k_e = F_Y / DELTA_E
    s = 0.5 * DELTA_E
    assert ab.update(s)[0] == pytest.approx(k_e * s)  # elastic: linear, below f_y
    assert ab.crush_stroke[0] == 0.0 and ab.absorbed_energy[0] == pytest.approx(0.0)
    forces = drive(ab, s, 0.15)
    plateau = forces[forces >= F_Y * (1 - 1e-12)]
    assert len(plateau) > 0.9 * len(forces)
    np.testing.assert_allclose(plateau, F_Y, rtol=1e-12)  # flat plateau at f_y
    assert ab.crush_stroke[0] == pytest.approx(0.15 - DELTA_E)


def test_absorber_densification_near_max_stroke() -> None:
    ab = make_absorber()
    forces = drive(ab, 0.0, S_MAX, 3000)
    strokes = np.linspace(0.0, S_MAX, 3000)
    assert np.all(np.diff(forces) >= -1e-9)  # monotone under loading
    assert forces[strokes < 0.8 * S_MAX - DELTA_E][-1] == pytest.approx(F_Y)
    assert forces[-1] == pytest.approx(5.0 * F_Y, rel=0.02)  # steep rise to 5 f_y
    # the last 5 % of the stroke adds more force than the whole plateau
    assert forces[-1] - forces[strokes >= 0.95 * S_MAX][0] > F_Y
    assert ab.bottomed_out[0]


def test_absorber_no_spring_back_load_unload_reload() -> None:
    ab = make_absorber()
    k_e = F_Y / DELTA_E
    drive(ab, 0.0, 0.1)
    crushed = ab.crush_stroke[0]
    assert crushed == pytest.approx(0.1 - DELTA_E)
    e_loaded = ab.absorbed_energy[0]

    # unload: down the stiff elastic line to zero at the crushed length ...
    assert ab.update(0.1 - 0.5 * DELTA_E)[0] == pytest.approx(0.5 * F_Y)
    assert ab.update(crushed)[0] == pytest.approx(0.0, abs=1e-9)
    # ... and no force at all below it (no spring-back, the crush is permanent)
    assert ab.update(0.05)[0] == 0.0
    assert ab.crush_stroke[0] == pytest.approx(crushed)
    # reload: elastic from the new crushed length, plateau only past the old peak
    assert ab.update(crushed + 0.25 * DELTA_E)[0] == pytest.approx(0.25 * k_e * DELTA_E)
    assert ab.update(0.1)[0] == pytest.approx(F_Y)
    assert ab.crush_stroke[0] == pytest.approx(crushed)
    assert ab.absorbed_energy[0] == pytest.approx(e_loaded)  # elastic cycle: no loss
    assert ab.update(0.12)[0] == pytest.approx(F_Y)
    assert ab.crush_stroke[0] == pytest.approx(0.12 - DELTA_E)


def test_absorber_quasi_static_energy_is_plateau_force_times_crush() -> None:
    ab = make_absorber(damping=5_000.0)  # damping irrelevant at zero stroke rate
    drive(ab, 0.0, 0.2, 200)
    assert ab.absorbed_energy[0] == pytest.approx(F_Y * ab.crush_stroke[0], rel=1e-9)
    assert ab.absorbed_energy[0] == pytest.approx(F_Y * (0.2 - DELTA_E), rel=1e-9)


def test_absorber_vectorized_pure_force_and_damping() -> None:
    ab = HoneycombAbsorber(
        3, f_y=np.array([1e3, 2e3, 4e3]), max_stroke=S_MAX, elastic_stroke=DELTA_E
    )
    f = ab.update(np.array([0.0, 0.05, 0.1]))
    np.testing.assert_allclose(f, [0.0, 2e3, 4e3])
    np.testing.assert_allclose(ab.crush_stroke, [0.0, 0.05 - DELTA_E, 0.1 - DELTA_E])
    before = ab.crush_stroke.copy()
    ab.force(np.full(3, 0.2))  # pure: no state change
    np.testing.assert_array_equal(ab.crush_stroke, before)

    ab = make_absorber(damping=1e5)
    ab.update(0.5 * DELTA_E, 0.0)
    # on the elastic line the viscous term adds force, capped by the envelope
    assert ab.force(0.5 * DELTA_E, 0.01)[0] == pytest.approx(0.5 * F_Y + 1e3)
    assert ab.force(0.5 * DELTA_E, 1.0)[0] == pytest.approx(F_Y)
    # while crushing the force is the plateau, whatever the rate
    assert ab.force(0.1, 3.0)[0] == pytest.approx(F_Y)
    ab.reset()
    assert ab.crush_stroke[0] == 0.0 and ab.absorbed_energy[0] == 0.0


# --- model --------------------------------------------------------------------------------


def _corners_and_centre() -> list[LanderDesign]:
    """The 8 corners of DESIGN_BOUNDS and its centre."""
    names = list(DESIGN_BOUNDS)
    corners = [
        LanderDesign(**{n: DESIGN_BOUNDS[n][bit] for n, bit in zip(names, bits, strict=True)})
        for bits in itertools.product((0, 1), repeat=len(names))
    ]
    centre = LanderDesign(**{n: 0.5 * sum(DESIGN_BOUNDS[n]) for n in names})
    return [*corners, centre]


@pytest.mark.parametrize(
    "design",
    _corners_and_centre(),
    ids=lambda d: f"fy{d.f_y:.0f}-beta{math.degrees(d.beta):.0f}-a{math.degrees(d.alpha2):.0f}",
)
def test_model_has_25_bodies_and_the_joint_types(design: LanderDesign) -> None:
    p = LanderParams()
    info = build_lander_model(design, p)
    m = info.model
    assert m.nbody - 1 == 25  # world body excluded
    names = [m.body(i).name for i in range(1, m.nbody)]
    for prefix in ("upper_", "lower_", "secondary_", "pad_"):
        assert sum(n.startswith(prefix) for n in names) == 6
    assert "chassis" in names
    types = np.bincount(m.jnt_type, minlength=4)
    assert types[mujoco.mjtJoint.mjJNT_FREE] == 1
    assert types[mujoco.mjtJoint.mjJNT_HINGE] == 6  # revolute
    assert types[mujoco.mjtJoint.mjJNT_BALL] == 12  # spherical
    assert types[mujoco.mjtJoint.mjJNT_SLIDE] == 6  # prismatic
    jtype = mujoco.mjtJoint
    for i in range(6):  # each joint on the body the topology puts it on
        for joint, body, kind in (
            (f"hinge_{i}", f"upper_{i}", jtype.mjJNT_HINGE),
            (f"slide_{i}", f"lower_{i}", jtype.mjJNT_SLIDE),
            (f"pad_ball_{i}", f"pad_{i}", jtype.mjJNT_BALL),
            (f"secondary_ball_{i}", f"secondary_{i}", jtype.mjJNT_BALL),
        ):
            assert m.jnt_type[m.joint(joint).id] == kind
            assert m.jnt_bodyid[m.joint(joint).id] == m.body(body).id
        assert m.body_parentid[m.body(f"upper_{i}").id] == info.chassis_body
        assert m.body_parentid[m.body(f"secondary_{i}").id] == info.chassis_body
        assert m.body_parentid[m.body(f"lower_{i}").id] == m.body(f"upper_{i}").id
        assert m.body_parentid[m.body(f"pad_{i}").id] == m.body(f"lower_{i}").id
    assert m.neq == 6 and np.all(m.eq_type == mujoco.mjtEq.mjEQ_CONNECT)
    # only pads and the chassis can collide, never with each other
    colliding = {m.geom(i).name for i in range(m.ngeom) if m.geom_contype[i]}
    assert colliding == {f"pad_geom_{i}" for i in range(6)} | {"chassis_geom"}
    assert not np.any(m.geom_conaffinity[[*info.pad_geoms, info.chassis_geom]])

    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    # loop closures satisfied in the initial configuration
    eq_rows = d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert eq_rows.sum() == 18 and np.abs(d.efc_pos[: d.nefc][eq_rows]).max() < 1e-9
    # geometry follows theta: strut inclination alpha2, leg azimuths from beta, pads
    # level and start_clearance above the ground
    for i in range(6):
        strut_up = d.xmat[m.body(f"upper_{i}").id].reshape(3, 3)[:, 2]
        assert math.acos(strut_up[2]) == pytest.approx(design.alpha2, abs=1e-9)
        pad = d.xpos[m.body(f"pad_{i}").id]
        assert math.atan2(pad[1], pad[0]) % (2 * math.pi) == pytest.approx(
            info.azimuths[i] % (2 * math.pi), abs=1e-9
        )
        assert d.xmat[m.body(f"pad_{i}").id].reshape(3, 3)[2, 2] == pytest.approx(1.0)
    np.testing.assert_allclose(info.azimuths, leg_azimuths(design.beta))
    pad_bottom = d.geom_xpos[info.pad_geoms, 2] - p.pad_half_thickness
    np.testing.assert_allclose(pad_bottom, p.start_clearance, atol=1e-9)


def test_body_count_does_not_depend_on_terrain() -> None:
    m = build_lander_model(DEFAULT_DESIGN).model
    rocky = build_lander_model(DEFAULT_DESIGN, terrain=Terrain(n_rocks=5), seed=3).model
    # rocks are static geoms of the world body
    assert rocky.nbody == m.nbody and rocky.ngeom == m.ngeom + 5


def test_sim_applies_absorber_force_on_slide_dofs_and_reset() -> None:
    sim = LanderSim(DEFAULT_DESIGN)
    model = sim.model
    while sim.time < 0.05:
        sim.step()
    assert np.all(sim.stroke > 0.0)
    np.testing.assert_array_equal(
        sim.data.qfrc_applied[sim.info.slide_dof], -sim.absorber.last_force
    )
    sim.reset(DEFAULT_DESIGN.replace(f_y=6000.0))  # f_y only: same compiled model
    assert sim.model is model and sim.absorber.f_y[0] == 6000.0
    assert sim.time == 0.0 and np.all(sim.absorber.crush_stroke == 0.0)
    sim.reset(DEFAULT_DESIGN.replace(alpha2=math.radians(20.0)))  # geometry: rebuild
    assert sim.model is not model


# --- touchdowns ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def default_landing() -> dict:
    return simulate_landing(DEFAULT_DESIGN)


@pytest.fixture(scope="module")
def stiff_landing() -> dict:
    return simulate_landing(DEFAULT_DESIGN.replace(f_y=8_000.0))


def test_flat_landing_comes_to_rest_upright(default_landing: dict) -> None:
    r = default_landing
    assert r["settled"] and r["t_end"] < LanderParams().max_time
    assert r["final_tilt"] < math.radians(1.0) and not r["tipped_over"]
    assert not r["bottomed_out"] and 0.0 < r["max_stroke"] < LanderParams().max_stroke
    assert np.all(r["crush_stroke_legs"] > 0.0)


def test_flat_landing_energy_balance(default_landing: dict) -> None:
    r = default_landing
    p = LanderParams()
    assert r["E_init"] == pytest.approx(p.total_mass * p.gravity * p.drop_height)
    assert r["KE_0"] == pytest.approx(r["E_init"])  # starts at the touchdown speed
    assert r["E_abs"] > 0.5 * r["E_init"]
    # what the absorbers dissipate cannot exceed the mechanical energy released:
    # initial kinetic energy (= E_init) + potential energy lost while stroking
    assert r["E_abs"] <= r["E_available"]
    assert r["E_available"] > r["KE_0"]  # the lander did sink
    assert r["E_abs"] <= r["E_init"] + r["KE_0"]
    assert r["J"] == pytest.approx(
        r["a_max"] / r["a_ref"] + (2.0 * (r["E_abs"] / r["E_init"] - 1.0)) ** 2
    )
    assert 1.0 < r["a_max"] / r["a_ref"] < 4.0


def test_stiffer_honeycomb_higher_acceleration_smaller_stroke(
    default_landing: dict, stiff_landing: dict
) -> None:
    soft, stiff = default_landing, stiff_landing
    assert stiff["a_max"] > 1.3 * soft["a_max"]
    assert stiff["max_stroke"] < 0.7 * soft["max_stroke"]
    assert stiff["settled"] and not stiff["bottomed_out"]


def test_landing_is_deterministic() -> None:
    terrain = Terrain(n_rocks=10)
    a = simulate_landing(DEFAULT_DESIGN, terrain=terrain, seed=3)
    b = simulate_landing(DEFAULT_DESIGN, terrain=terrain, seed=3)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    # seed 3 puts rocks under some pads: the legs stroke unevenly
    assert np.ptp(a["max_stroke_legs"]) > 0.01


def test_slope_landing_stays_upright() -> None:
    r = simulate_landing(DEFAULT_DESIGN, terrain=Terrain(slope=math.radians(10.0)))
    assert not r["tipped_over"] and r["E_abs"] > 0.0
    assert r["E_abs"] <= r["E_available"]


def test_terrain_validation() -> None:
    with pytest.raises(ValueError, match="slope"):
        Terrain(slope=math.radians(45.0))
    with pytest.raises(ValueError, match="n_rocks"):
        Terrain(n_rocks=-1)


@pytest.mark.skipif(
    __import__("chronogym.engines.mujoco", fromlist=["gl_unavailable"]).gl_unavailable()
    is not None,
    reason="no offscreen OpenGL (EGL or OSMesa)",
)
def test_lander_renders_offscreen() -> None:
    import numpy as np

    from chronogym.tasks.lander import LanderSim

    sim = LanderSim()
    frame = sim.render(width=160, height=120)
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8 and frame.std() > 5.0
