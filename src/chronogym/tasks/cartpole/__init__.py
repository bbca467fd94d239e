"""Cart-pole balancing, one module per engine: :mod:`.mujoco` (``CartPoleTask``, the model in
``cartpole.xml``; id ``chronogym/CartPole-v0``) and :mod:`.chrono` (``ChronoCartPoleTask``,
id ``chronogym/ChronoCartPole-v0``; PyChrono is imported only when its system is built)."""

from chronogym.tasks.cartpole.chrono import ChronoCartPoleTask
from chronogym.tasks.cartpole.mujoco import XML_PATH, CartPoleTask

__all__ = ["XML_PATH", "CartPoleTask", "ChronoCartPoleTask"]
