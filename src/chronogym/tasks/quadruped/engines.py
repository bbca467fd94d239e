"""Which engines run the Go1, on which terrains, under which Gymnasium id: defined here once.

The MuJoCo task (:mod:`.task`), the Chrono task (:mod:`.chrono_task`), the training and play
helpers and the CLI's ``--engine`` / ``--terrain`` choices all read these names. Light on
purpose (no MuJoCo, no PyChrono at import), so the CLI parser can import it.
"""

from __future__ import annotations

from typing import Any

from chronogym.engines.chrono import import_pychrono

#: Gymnasium id of the MuJoCo Go1 task.
ENV_ID = "chronogym/Go1Velocity-v0"
#: Gymnasium id of the Go1 task per engine; both share observation, action and reward.
ENV_IDS: dict[str, str] = {
    "mujoco": ENV_ID,
    "chrono": "chronogym/ChronoGo1Velocity-v0",
}
#: Terrains of the Go1 task per engine: MuJoCo's floor or chronogym's SCM soil over it;
#: Chrono's rigid box or its own SCMTerrain.
ENGINE_TERRAINS: dict[str, tuple[str, ...]] = {
    "mujoco": ("rigid", "soil"),
    "chrono": ("rigid", "scm"),
}
#: The engines that run the Go1 task.
ENGINES: tuple[str, ...] = tuple(ENV_IDS)
#: Every terrain some engine runs, in order (the CLI's ``--terrain`` choices).
ALL_TERRAINS: tuple[str, ...] = tuple(
    dict.fromkeys(terrain for terrains in ENGINE_TERRAINS.values() for terrain in terrains)
)


def check_engine(engine: str, terrain: str = "rigid") -> str:
    """The Gymnasium id for ``engine``, after checking that it runs ``terrain`` and, for
    Chrono, that PyChrono imports (ValueError / ModuleNotFoundError naming what to do)."""
    if engine not in ENV_IDS:
        raise ValueError(f"engine={engine!r}: expected one of {', '.join(ENV_IDS)}")
    terrains = ENGINE_TERRAINS[engine]
    if terrain not in terrains:
        others = [e for e, ts in ENGINE_TERRAINS.items() if terrain in ts]
        hint = f" (terrain {terrain!r} runs on engine {others[0]!r})" if others else ""
        raise ValueError(
            f"terrain={terrain!r}: expected one of {', '.join(terrains)} on engine {engine!r}{hint}"
        )
    if engine == "chrono":
        import_pychrono()
    return ENV_IDS[engine]


def env_kwargs_for(
    terrain: str, task_kwargs: dict[str, Any] | None = None, engine: str = "mujoco"
) -> dict[str, Any]:
    """Keyword arguments of the task for a terrain name, plus ``task_kwargs`` (other
    ``Go1VelocityTask`` arguments, e.g. ``{"dt": 0.005, "k": 4}``)."""
    terrains = ENGINE_TERRAINS.get(engine, ENGINE_TERRAINS["mujoco"])
    if terrain not in terrains:
        raise ValueError(f"terrain={terrain!r}: expected one of {terrains} on engine {engine!r}")
    extra = dict(task_kwargs or {})
    if "terrain" in extra:
        raise ValueError(
            f"task_kwargs={task_kwargs!r}: give the terrain as terrain=..., not in task_kwargs"
        )
    return {**({} if terrain == "rigid" else {"terrain": terrain}), **extra}
