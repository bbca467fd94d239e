"""A default Ray run is quiet: no Ray auth advice, no MuJoCo deprecation, no empty worker lines."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import ray

    from chronogym import RayVectorEnv

    ray.init(num_cpus=2, include_dashboard=False)
    # Gymnasium's half_cheetah.xml sets the deprecated ``settotalmass``
    env = RayVectorEnv("HalfCheetah-v5", 2, envs_per_worker=1, num_cpus=0.5)
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    env.close()
    print("DONE")
    """
)


def test_a_ray_rollout_prints_none_of_the_known_noise(tmp_path):
    run = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    assert "DONE" in run.stdout
    assert "RAY_AUTH_MODE" not in out and "Token authentication" not in out
    assert "settotalmass" not in out
    assert not re.search(r"\(\w+ pid=\d+\)\s*$", out, re.MULTILINE), out  # empty worker lines
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()  # MuJoCo's default handler writes one


def test_other_mujoco_warnings_still_print(capfd):
    from chronogym.ray_runtime import _mujoco_warning

    _mujoco_warning("compiler attribute 'settotalmass' is deprecated and will be removed")
    _mujoco_warning("Nan, Inf or huge value in QACC at DOF 0.")
    err = capfd.readouterr().err
    assert err == "MuJoCo warning: Nan, Inf or huge value in QACC at DOF 0.\n"


def test_ray_auth_filter_drops_only_the_opt_out_advice():
    import logging

    from chronogym.ray_runtime import RAY_AUTH_LOGGER

    records = []
    handler = logging.Handler()
    handler.emit = records.append
    ray_logger = logging.getLogger(RAY_AUTH_LOGGER)
    ray_logger.addHandler(handler)
    try:
        ray_logger.warning("Token authentication is enabled for this Ray cluster. Set ...")
        ray_logger.warning("Token authentication is disabled for this Ray cluster. Anyone ...")
    finally:
        ray_logger.removeHandler(handler)
    assert [r.getMessage()[:37] for r in records] == ["Token authentication is disabled for "]


def test_the_mujoco_handler_waits_for_mujocos_own_import(tmp_path):
    script = textwrap.dedent(
        """
        import sys
        from chronogym.ray_runtime import _mujoco_warning, quiet_mujoco_warnings

        quiet_mujoco_warnings()
        assert "mujoco" not in sys.modules  # a worker without MuJoCo envs never imports it
        import mujoco
        from pathlib import Path
        import gymnasium.envs.mujoco as gym_mujoco

        assert mujoco.get_mju_user_warning() is _mujoco_warning
        xml = Path(gym_mujoco.__file__).parent / "assets" / "half_cheetah.xml"
        mujoco.MjModel.from_xml_path(str(xml))  # sets settotalmass
        print("OK")
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0 and run.stdout == "OK\n" and run.stderr == "", run.stderr
