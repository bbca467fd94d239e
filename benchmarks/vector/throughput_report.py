"""What the sweep of ``throughput.py`` measured, against AsyncVectorEnv and the raw loop.

Not a script. :func:`derive` adds to every result its ratio to AsyncVectorEnv at the same N
and cost (``x_async``) and its parallel efficiency against the raw single-env loop; then the
sweep's table and notes, the goal table per transport (the scale-out goals: ``x_async`` >= 1.0
everywhere and >= 1.5 on the cheapest cost, ``eff`` >= 0.9 where one call carries >= 1 ms of
physics) and the JSON record.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from typing import Any

from benchmarks.common import Column, header, settings, table
from benchmarks.vector.throughput_sweep import VECTOR_BACKENDS, Result
from benchmarks.vector.throughput_timing import (
    DEFAULT_TRANSPORT,
    DT,
    ENV_ID,
    SHAPE_COLUMNS,
    TASK_KWARGS,
)


def derive(results: list[Result], cpus: int) -> None:
    """Fill each result's ratio to AsyncVectorEnv, efficiency and physics per remote call."""
    raw = {r.config.level.k: r.sim_steps_per_s for r in results if r.config.backend == "raw"}
    asyncs = {
        (r.config.level.k, r.config.num_envs): r.sim_steps_per_s
        for r in results
        if r.config.backend == "async"
    }
    for r in results:
        c = r.config
        base = raw[c.level.k]
        physics_us = 1e6 / base
        ref = asyncs.get((c.level.k, c.num_envs)) if c.backend in VECTOR_BACKENDS else None
        r.derived = {
            "physics_us_per_step": physics_us,
            "physics_us_per_call": c.envs_per_worker * physics_us,
            "vs_async": r.sim_steps_per_s / ref if ref else None,
            "efficiency": r.sim_steps_per_s / (c.workers * base),
            "efficiency_per_cpu": r.sim_steps_per_s / (min(c.workers, cpus) * base),
        }


COLUMNS = (
    Column("phys/step", 10, "{:.0f}µs"),
    Column("backend", 9),
    *SHAPE_COLUMNS,
    Column("phys/call", 9, "{:.2f}ms"),
    Column("steps/s", 9, "{:.0f}"),
    Column("sim-st/s", 9, "{:.0f}"),
    Column("µs/vstep", 9, "{:.0f}"),
    Column("x_async", 6, "{:.2f}"),
    Column("eff", 5, "{:.2f}"),
    Column("eff/cpu", 7, "{:.2f}"),
)


def row_values(r: Result) -> list[Any]:
    """The table cells of one result, in COLUMNS order."""
    c, d = r.config, r.derived
    return [
        d["physics_us_per_step"],
        c.backend,
        c.num_envs,
        c.workers,
        c.envs_per_worker,
        d["physics_us_per_call"] / 1000,  # type: ignore[operator]
        r.steps_per_s,
        r.sim_steps_per_s,
        r.us_per_call,
        d["vs_async"],
        d["efficiency"],
        d["efficiency_per_cpu"],
    ]


def format_table(results: list[Result]) -> str:
    """Aligned text table; a blank line between cost levels."""
    rows: list[list[Any] | None] = []
    for i, r in enumerate(results):
        if i and r.config.level.k != results[i - 1].config.level.k:
            rows.append(None)
        rows.append(row_values(r))
    return table(COLUMNS, rows, rule=True)


def notes(cpus: int, tick_us: float, results: list[Result]) -> str:
    """The explanations printed under the table."""
    ks = ", ".join(
        f"k={r.config.level.k} -> {r.derived['physics_us_per_step']:.0f} µs"
        for r in results
        if r.config.backend == "raw"
    )
    return "\n".join(
        [
            f"physics tick (mj_step) = {tick_us:.2f} µs; per env step (raw loop): {ks}",
            "steps/s counts autoreset steps (no physics); sim-st/s counts steps that ran "
            "physics, and x_async / eff use it.",
            "eff = sim-steps/s / (workers x raw single-env rate); eff/cpu uses min(workers, "
            "CPUs) instead; wrk = Ray workers, Async processes, 1 for serial.",
            "phys/call = envs per worker x physics per env step (what one remote call carries).",
            *(
                ["ray-async = send / recv(min_envs=N/2) (µs/vstep: per recv) vs ray's barrier."]
                if any(r.config.min_envs for r in results)
                else []
            ),
            f"NOTE: this machine has {cpus} CPU(s). More than {cpus} busy processes (Async with "
            f"N > {cpus}, Ray with more than {cpus} workers, plus the driver) oversubscribe the "
            "cores: their eff is bounded by CPUs / workers, and all numbers are noisy when the "
            "machine is shared.",
        ]
    )


def sweep_record(args: argparse.Namespace, tick_us: float, results: list[Result]) -> dict[str, Any]:
    """Machine info, settings, cost levels and every result, for the JSON."""
    levels = [
        {**asdict(r.config.level), "physics_us_per_step": r.derived["physics_us_per_step"]}
        for r in results
        if r.config.backend == "raw"
    ]
    return {
        **header("chronogym throughput (cart-pole)"),
        "env_id": ENV_ID,
        "dt": DT,
        "task_kwargs": TASK_KWARGS,
        "settings": settings(args),
        "tick_us": tick_us,
        "default_transport": DEFAULT_TRANSPORT,
        "cost_levels": levels,
        "results": [result_record(r) for r in results],
    }


def result_record(r: Result) -> dict[str, Any]:
    """One result as a flat JSON record."""
    c = r.config
    return {
        "backend": c.backend,
        "num_envs": c.num_envs,
        "workers": c.workers,
        "envs_per_worker": c.envs_per_worker,
        "min_envs": c.min_envs or None,
        "k": c.level.k,
        "target_us": c.level.target_us,
        "env_steps": r.env_steps,
        "sim_steps": r.sim_steps,
        "calls": r.calls,
        "seconds": r.seconds,
        "setup_s": r.setup_s,
        "steps_per_s": r.steps_per_s,
        "sim_steps_per_s": r.sim_steps_per_s,
        "us_per_call": r.us_per_call,
        **r.derived,
    }


# -- goals ----------------------------------------------------------------------------------

CHEAP_X_ASYNC = 1.5  # goal on the cheapest cost level
X_ASYNC = 1.0  # goal at every cost level
EFFICIENCY = 0.9  # goal where one remote call carries >= EFFICIENCY_MIN_CALL_MS of physics
EFFICIENCY_MIN_CALL_MS = 1.0


def best_rows(results: list[Result], backend: str) -> list[Result]:
    """Per (cost level, N): the ``backend`` row with the most sim-steps/s."""
    best: dict[tuple[int, int], Result] = {}
    for r in results:
        key = (r.config.level.k, r.config.num_envs)
        if r.config.backend == backend and (
            key not in best or r.sim_steps_per_s > best[key].sim_steps_per_s
        ):
            best[key] = r
    return list(best.values())


GOAL_COLUMNS = (
    Column("phys/step", 10, "{:.0f}µs"),
    *SHAPE_COLUMNS,
    Column("phys/call", 9, "{:.2f}ms"),
    Column("x_async", 7, "{:.2f}"),
    Column("goal", 5),
    Column("eff", 5, "{:.2f}"),
    Column("goal", 5),
)


def goal_table(results: list[Result], backend: str) -> str:
    """x_async and efficiency of ``backend``'s best shape per cost level and N, with the goals."""
    cheapest = min(r.config.level.k for r in results)
    rows = []
    for r in best_rows(results, backend):
        c, d = r.config, r.derived
        x_goal = CHEAP_X_ASYNC if c.level.k == cheapest else X_ASYNC
        x_ok = d["vs_async"] is not None and d["vs_async"] >= x_goal
        call_ms = d["physics_us_per_call"] / 1000  # type: ignore[operator]
        eff_ok = "-" if call_ms < EFFICIENCY_MIN_CALL_MS else ok(d["efficiency"] >= EFFICIENCY)
        rows.append(
            [
                d["physics_us_per_step"],
                c.num_envs,
                c.workers,
                c.envs_per_worker,
                call_ms,
                d["vs_async"] or 0,
                ok(x_ok),
                d["efficiency"],
                eff_ok,
            ]
        )
    return (
        f"goals for {backend} (best shape per row): x_async >= {X_ASYNC} everywhere, >= "
        f"{CHEAP_X_ASYNC} on the cheapest cost; eff >= {EFFICIENCY} where phys/call >= "
        f"{EFFICIENCY_MIN_CALL_MS:g} ms\n" + table(GOAL_COLUMNS, rows)
    )


def ok(passed: bool) -> str:
    """A goal's cell: ``ok`` or ``MISS``."""
    return "ok" if passed else "MISS"
