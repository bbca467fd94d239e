"""A soil window that follows its bodies: same physics and ruts as one large field, the ruts it
leaves are archived and come back, reset puts it back, bad settings are named."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from chronogym.terrain import MujocoSoil
from chronogym.terrain.archive import TILE, TileArchive

BALL = """<mujoco><option timestep="0.001"/><worldbody>
  <geom name="floor" type="plane" size="0 0 1"/>
  <body name="ball" pos="{x} 0 0.06"><freejoint/><geom type="sphere" size="0.05" mass="2"/></body>
  <body name="cart" pos="0 3 0.06"><freejoint/><geom type="sphere" size="0.05" mass="2"/></body>
</worldbody></mujoco>"""


def _drive(x0: float, steps: int, **soil_kwargs):
    """A ball pushed towards +x at 1 m/s over soft soil; returns (positions, soil)."""
    model = mujoco.MjModel.from_xml_string(BALL.format(x=x0))
    data = mujoco.MjData(model)
    soil = MujocoSoil(model, data, "soft", bodies=["ball"], resolution=0.01, **soil_kwargs)
    soil.exclude_ground("floor")
    path = []
    for _ in range(steps):
        soil.Advance(model.opt.timestep)
        data.xfrc_applied[1, 0] += 40.0 * (1.0 - data.qvel[0])
        mujoco.mj_step(model, data)
        path.append(data.qpos[:3].copy())
    return np.array(path), soil


def _whole_field(soil: MujocoSoil, reference: MujocoSoil) -> np.ndarray:
    """Plastic sinkage of a following soil (window + archive) over ``reference``'s nodes."""
    grid = soil.grid
    archive = TileArchive((0.0, 0.0))
    archive.tiles = {key: tile.copy() for key, tile in grid.archive.tiles.items()}
    archive.store([grid.interior(grid.level0), grid.interior(grid.plastic)], grid.offset)
    start = [
        round((reference.grid.x[0] - grid.x[0]) / grid.resolution) + grid.offset[0],
        round((reference.grid.y[0] - grid.y[0]) / grid.resolution) + grid.offset[1],
    ]
    rows = [np.zeros(reference.grid.shape), np.zeros(reference.grid.shape)]
    archive.load(rows, tuple(start))
    return rows[1]


def test_a_following_window_matches_one_large_field():
    fixed_path, fixed = _drive(-1.5, 2500, extent=(4.0, 1.0))
    moving_path, moving = _drive(-1.5, 2500, extent=(0.6, 0.6), follow=True)
    assert fixed_path[-1, 0] > 0.3  # it rolled ~1.9 m: the window moved many times
    assert moving.grid.offset[0] > 20  # from -150 (x = -1.5) to the end
    np.testing.assert_allclose(moving_path, fixed_path, rtol=0, atol=1e-9)
    ruts = _whole_field(moving, fixed)
    assert fixed.plastic_sinkage.max() > 0.01
    np.testing.assert_allclose(ruts, fixed.plastic_sinkage, rtol=0, atol=1e-9)
    # Only tiles along the track are stored: a 0.1 m ball needs one row of tiles.
    rows = {key[1] for key in moving.grid.archive.tiles}
    assert len(rows) <= 2 and moving.grid.archive.nbytes < 2e6


def test_reset_brings_the_window_back_and_forgets_the_ruts():
    first, soil = _drive(-1.0, 800, extent=(0.6, 0.6), follow=True)
    assert soil.grid.offset != (0, 0) and len(soil.grid.archive) > 0
    soil.reset()
    assert soil.grid.offset == (0, 0) and len(soil.grid.archive) == 0
    assert soil.plastic_sinkage.max() == 0.0
    np.testing.assert_array_equal(soil.grid.x[[0, -1]], [-0.3, 0.3])
    mujoco.mj_resetData(soil.model, soil.data)
    again = []
    for _ in range(800):
        soil.Advance(soil.model.opt.timestep)
        soil.data.xfrc_applied[1, 0] += 40.0 * (1.0 - soil.data.qvel[0])
        mujoco.mj_step(soil.model, soil.data)
        again.append(soil.data.qpos[:3].copy())
    np.testing.assert_array_equal(np.array(again), first)  # bit for bit after reset


def test_the_archive_keeps_only_deformed_tiles_and_restores_them():
    archive = TileArchive((1.0, 0.0))
    level, plastic = np.ones((70, 40)), np.zeros((70, 40))
    plastic[65, 5] = 0.02
    archive.store([level, plastic], (-10, 3))
    assert list(archive.tiles) == [((65 - 10) // TILE, (5 + 3) // TILE)]
    rows = [np.zeros((5, 5)), np.full((5, 5), 9.0)]
    archive.load(rows, (53, 6))
    assert rows[0].tolist() == np.ones((5, 5)).tolist()
    assert rows[1][2, 2] == 0.02 and np.count_nonzero(rows[1]) == 1


def test_follow_settings_are_checked():
    model = mujoco.MjModel.from_xml_string(BALL.format(x=0))
    data = mujoco.MjData(model)
    with pytest.raises(ValueError, match="follow with an array level"):
        MujocoSoil(model, data, "soft", bodies=["ball"], level=np.zeros((3, 3)),
                   extent=(0.04, 0.04), follow=True)  # fmt: skip
    with pytest.raises(ValueError, match="2 root bodies"):
        MujocoSoil(model, data, "soft", bodies=["ball", "cart"], follow=True)
    with pytest.raises(ValueError, match="body 'nope'"):
        MujocoSoil(model, data, "soft", bodies=["ball"], follow="nope")
    soil = MujocoSoil(model, data, "soft", bodies=["ball", "cart"], follow="cart")
    assert soil.follow_body == model.body("cart").id
