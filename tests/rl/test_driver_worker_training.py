"""Training with ``driver_worker=True``: the training process steps one worker's envs."""

from __future__ import annotations

import pytest

from chronogym.rl import train_quadruped


def test_trains_and_saves_with_the_driver_as_a_worker(ray_cluster, tmp_path):
    result = train_quadruped(
        tmp_path, num_envs=4, envs_per_worker=2, iterations=2, driver_worker=True, progress=False
    )
    assert result.iterations_done == 2
    assert result.checkpoint.is_file()


def test_driver_worker_needs_the_ray_backend(tmp_path):
    with pytest.raises(ValueError, match="driver_worker=True with backend='serial'"):
        train_quadruped(tmp_path, backend="serial", iterations=1, driver_worker=True)
