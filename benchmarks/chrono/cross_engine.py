"""The lander in MuJoCo and in Project Chrono: the same designs dropped on rigid ground.

``LanderSim`` (MuJoCo) and ``ChronoLanderSim`` (PyChrono, ``chronogym.tasks.lander.chrono.sim``)
build the same 25 bodies (Chrono reads MuJoCo's masses and inertias), the same joints and the
same honeycomb law, and compute the metrics with the same code (``landing.Landing``). Each
design lands once per engine at its default settings (MuJoCo 0.5 ms; Chrono 0.25 ms, SMC
contact, ``ChronoSettings``); the table prints ``a_max``, ``E_abs``, the largest stroke and
``J`` per engine and the relative difference Chrono / MuJoCo - 1, plus the wall time of a
landing. ``--convergence`` also lands the default design in Chrono at 0.5, 0.25 and 0.125 ms.

What differs between the engines, and why the numbers do (the committed run: the default
design within 2 % on a_max, E_abs, stroke and J; see docs/performance/chrono.md):

* **Knee loops.**  Chrono enforces every joint exactly (direct sparse LU); MuJoCo closes the
  six knee loops with soft ``connect`` equalities (4 ms time constant), which take work:
  302 J of a default landing (``energy["joint_loops"]``), 2033 J at wide legs (``alpha2``
  = 50 deg), where the pads' friction bends the legs hardest.  That is the gap at
  ``wide_bunched``: Chrono's ``E_abs`` +14 %, stroke +15 %, ``a_max`` -6 %.  Stiffening
  MuJoCo's constraints moves it towards Chrono's rigid truss: at 4 / 2 / 1 ms its
  ``E_abs`` there is 2278 / 2540 / 2672 J and ``a_max`` 50.6 / 49.2 / 44.8 m/s^2 (0.25
  ms steps), against Chrono's 2591 J and 47.7 m/s^2.
* **Bottoming out** (``softest``, 1 kN: the struts hit their stops).  MuJoCo's soft joint
  limit against Chrono's implicit spring-damper of the same time constant, in series with
  the pads' penalty contacts: the peak then rides on those numerical stiffnesses.
  Chrono's is 15 % higher, inside the 119-145 m/s^2 that MuJoCo's own ``a_max`` spans
  between constraint time constants of 4 and 1 ms; both rank the design far worst.
* **Contact.**  MuJoCo: soft constraints solved implicitly each step, elliptic friction
  cone, 3 contacts per pad.  Chrono: penalty contacts (SMC, Hooke) on a ring of 8 points
  per pad, explicit forces, Coulomb friction regularized as a viscous law capped at
  ``mu F_n``, so slow slips (below about 0.1 m/s) see less than Coulomb friction.  The
  stiffness is set to MuJoCo's observed 3 mm touchdown sink (``ChronoSettings``); the
  stiffest honeycomb is the design that feels it (``a_max`` 66.2 at half the stiffness,
  68.9 at the default, MuJoCo 68.9).
* **Settling.**  Both landers hop after the crush (the honeycombs' elastic line gives
  back ``f_y d_e / 2`` per leg) and settle when the chassis is still for 0.1 s; Chrono's
  penalty contacts and missing joint damping make the times differ (``t_end``).
* **Integration.**  MuJoCo ``implicitfast`` at 0.5 ms is converged (0.125 ms changes
  ``a_max`` by < 0.1 %).  Chrono's first-order implicit Euler with explicit contact forces
  needs 0.25 ms (``--convergence``: within 0.6 % of 0.125 ms; 0.5 ms is 3 % low).
* **Cost.**  A Chrono landing is 5-18x dearer: ~1 ms per 0.25 ms step (the sparse LU
  about 0.7 ms, the Python side of the tick 0.3 ms) against MuJoCo's ~0.1 ms per 0.5 ms.

    python -m benchmarks.chrono.cross_engine [--convergence] [--out JSON]

The JSON goes to ``benchmarks/results/cross_engine.json`` unless ``--out`` names another file.

Needs PyChrono (``conda install projectchrono::pychrono -c conda-forge``); without it the
script says so and exits with status 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import RESULTS, header, pyplot, save_figure, versions, write_json
from chronogym.engines.chrono import import_pychrono
from chronogym.tasks.lander import DEFAULT_DESIGN, LanderDesign, LanderParams, LanderSim

DEFAULT_OUT = RESULTS / "cross_engine.json"
#: name -> design: the default and one at each bound of every design variable.
DESIGNS: dict[str, LanderDesign] = {
    "default": DEFAULT_DESIGN,
    "softest": LanderDesign.from_degrees(1_000.0, 60.0, 30.0),
    "stiffest": LanderDesign.from_degrees(15_000.0, 60.0, 30.0),
    "wide_bunched": LanderDesign.from_degrees(4_000.0, 20.0, 50.0),
    "upright_spread": LanderDesign.from_degrees(8_000.0, 100.0, 10.0),
}
COMPARED = ("a_max", "E_abs", "max_stroke", "J")
KEPT = (*COMPARED, "a_max_proper", "bottomed_out", "tipped_over", "settled", "t_end", "n_steps")


def land(sim: Any) -> dict[str, Any]:
    """Run a landing; its metrics, wall time and filtered chassis acceleration history."""
    start = time.perf_counter()
    metrics = sim.run()
    wall = time.perf_counter() - start
    acc = np.linalg.norm(sim.chassis_acceleration(), axis=1)
    row = {key: _plain(metrics[key]) for key in KEPT}
    row["wall_s"] = wall
    row["timestep"] = sim.params.timestep
    row["energy"] = {key: float(value) for key, value in metrics["energy"].items()}
    row["diverged"] = bool(sim.diverged())
    return {"row": row, "acc": acc, "dt": sim.params.timestep}


def _plain(value: Any) -> Any:
    return value if isinstance(value, (bool, type(None))) else float(value)


def relative(chrono: dict[str, Any], mujoco_row: dict[str, Any]) -> dict[str, float]:
    """Chrono / MuJoCo - 1 for each compared metric."""
    return {key: chrono[key] / mujoco_row[key] - 1.0 for key in COMPARED}


def print_table(results: dict[str, dict[str, Any]]) -> None:
    head = f"{'design':>15} {'engine':>7} {'a_max':>7} {'E_abs':>7} {'stroke':>7} {'J':>6}"
    print(f"{head} {'settled':>7} {'t_end':>6} {'wall_s':>7}")
    for name, r in results.items():
        for engine in ("mujoco", "chrono"):
            row = r[engine]
            print(
                f"{name:>15} {engine:>7} {row['a_max']:7.2f} {row['E_abs']:7.0f} "
                f"{row['max_stroke']:7.4f} {row['J']:6.3f} {row['settled']!s:>7} "
                f"{row['t_end']:6.2f} {row['wall_s']:7.2f}"
            )
        rel = r["relative"]
        print(
            f"{'':>15} {'diff':>7} "
            + " ".join(f"{100 * rel[k]:+6.1f}%" for k in ("a_max", "E_abs", "max_stroke"))
            + f" {100 * rel['J']:+5.1f}%"
        )


def plot(histories: dict[str, dict[str, Any]], path: Path) -> bool:
    """|a| (20 ms box filter) against time per design and engine; False without matplotlib."""
    try:
        plt = pyplot()
    except ImportError:
        return False
    fig, axes = plt.subplots(1, len(histories), figsize=(4 * len(histories), 3.4), sharey=False)
    for ax, (name, engines) in zip(np.atleast_1d(axes), histories.items(), strict=True):
        for engine, style in (("mujoco", "-"), ("chrono", "--")):
            h = engines[engine]
            t = np.arange(len(h["acc"])) * h["dt"]
            keep = t < 0.5
            ax.plot(t[keep], h["acc"][keep], style, label=engine)
        ax.set_title(name)
        ax.set_xlabel("t [s]")
    np.atleast_1d(axes)[0].set_ylabel("|a| chassis, 20 ms box [m/s²]")
    np.atleast_1d(axes)[0].legend()
    save_figure(fig, path, dpi=90)
    return True


def convergence(chrono_sim: type, settings: type) -> list[dict[str, Any]]:
    """The default design in Chrono at 0.5, 0.25 and 0.125 ms."""
    rows = []
    for dt in (0.0005, 0.00025, 0.000125):
        out = land(chrono_sim(DEFAULT_DESIGN, settings=settings(timestep=dt)))
        rows.append(out["row"])
        row = out["row"]
        print(
            f"  Chrono dt {dt * 1e3:5.3f} ms: a_max {row['a_max']:.2f}, E_abs {row['E_abs']:.0f}, "
            f"stroke {row['max_stroke']:.4f}, J {row['J']:.3f} ({row['wall_s']:.1f} s)"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument(
        "--convergence", action="store_true", help="default design in Chrono at 3 time steps"
    )
    parser.add_argument("--designs", nargs="+", choices=list(DESIGNS), default=list(DESIGNS))
    args = parser.parse_args()
    try:
        import_pychrono()
    except ModuleNotFoundError as exc:
        sys.exit(f"cross_engine.py needs PyChrono: {exc}")
    from chronogym.tasks.lander.chrono.model import ChronoSettings
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    params = LanderParams()
    results: dict[str, dict[str, Any]] = {}
    histories: dict[str, dict[str, Any]] = {}
    for name in args.designs:
        design = DESIGNS[name]
        mj = land(LanderSim(design, params))
        ch = land(ChronoLanderSim(design, params))
        results[name] = {
            "design": dataclasses.asdict(design),
            "mujoco": mj["row"],
            "chrono": ch["row"],
            "relative": relative(ch["row"], mj["row"]),
        }
        histories[name] = {"mujoco": mj, "chrono": ch}
        walls = mj["row"]["wall_s"], ch["row"]["wall_s"]
        print(f"landed {name} ({walls[0]:.1f} s MuJoCo, {walls[1]:.1f} s Chrono)", flush=True)
    print()
    print_table(results)
    steps = convergence(ChronoLanderSim, ChronoSettings) if args.convergence else []
    png = args.out.with_suffix(".png")
    plotted = plot(histories, png)
    result = {
        **header("cross_engine", "pychrono"),
        # also top-level keys, as in the committed JSON
        "python": platform.python_version(),
        **versions("mujoco", "pychrono", "numpy"),
        "params": dataclasses.asdict(params),
        "chrono_settings": dataclasses.asdict(ChronoSettings()),
        "designs": results,
        "chrono_convergence": steps,
    }
    write_json(args.out, result, f" and {png}" if plotted else " (no matplotlib: no plot)")
    if not math.isfinite(sum(r["chrono"]["J"] for r in results.values())):
        sys.exit("a Chrono landing gave a non-finite J")


if __name__ == "__main__":
    main()
