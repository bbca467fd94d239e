"""Tasks shipped with chronogym, one package per task; the engine shows in the path.

* ``cartpole/`` -- ``mujoco.py`` (``CartPoleTask``, ``chronogym/CartPole-v0``) and ``chrono.py``
  (``ChronoCartPoleTask``, ``chronogym/ChronoCartPole-v0``): one module per engine.
* ``quadruped/`` -- the Go1 and its velocity-tracking task: MuJoCo only, so no engine folder.
* ``lander/`` -- the engine-independent design, absorber, geometry, terrain and landing
  metrics at the top; ``mujoco/`` and ``chrono/`` each hold that engine's model and simulation.

PyChrono is optional: nothing here imports it at module import.
"""
