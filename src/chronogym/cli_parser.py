"""The ``chronogym`` command line's arguments: every option with a help text and its default.

A value out of range (``--num-envs 0``) or a choice that does not exist (``chronogym train
biped``) is rejected while parsing, in two lines on stderr (what was wrong, where the help is)
and exit status 2, before anything heavy is imported or started.
"""

from __future__ import annotations

import argparse
import sys
from importlib.metadata import PackageNotFoundError, version
from typing import Any, NoReturn

from chronogym.optim.lander import ENGINES as LANDER_ENGINES
from chronogym.optim.lander import TERRAINS as LANDER_TERRAINS
from chronogym.tasks.quadruped.engines import ALL_TERRAINS, ENGINES

DEFAULT_STORAGE = "sqlite:///chronogym-optuna.db"
QUADRUPED_ENGINES = list(ENGINES)
QUADRUPED_ENGINE_HELP = "physics engine (chrono: needs PyChrono; a MuJoCo checkpoint runs there)"
QUADRUPED_TERRAINS = list(ALL_TERRAINS)
QUADRUPED_TERRAIN_HELP = (
    "rigid ground; soil: chronogym's SCM (engine mujoco); scm: Chrono's SCMTerrain (engine chrono)"
)
DEBUG_HELP = "show the traceback of an error, as CHRONOGYM_DEBUG=1 does (default: off)"
ENVS_PER_WORKER_HELP = "envs stepped by one Ray worker (default: num-envs spread over the CPUs)"
ADDRESS_HELP = "Ray cluster address (default: RAY_ADDRESS, else a new local cluster)"
BACKEND_HELP = "ray: envs on Ray workers; serial: all in this process, no Ray"


#: Each subcommand: its one-line summary in ``chronogym --help``, and its description.
COMMAND_TEXTS = {
    "demo": (
        "run a short parallel cart-pole demo on Ray",
        "Run the cart-pole on Ray workers and check its trajectories against a serial run.",
    ),
    "optimize": (
        "parallel Bayesian optimization of a design",
        "Optimize the lander's absorbers with Optuna TPE, trials on parallel Ray workers.",
    ),
    "train": (
        "train a policy with PPO (RSL-RL) on parallel envs",
        "Train the Go1 velocity tracker with PPO (RSL-RL) on Ray workers or serially.",
    ),
    "play": (
        "roll out a trained policy, print errors, save a video",
        "Roll a trained policy out for a set of commands; print tracking errors, save a video.",
    ),
    "envs": (
        "list registered environment ids, or describe one",
        "List the registered chronogym environment ids; with an id, describe that environment.",
    ),
    "bench": (
        "size a parallel run: measure an env's costs, predict efficiency",
        "Time an env's step, then the vector env's fixed and per-worker costs; print the "
        "expected parallel efficiency for workers x envs per worker, and recommend both.",
    ),
}


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are two lines: the problem, then where help is."""

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: {message}", file=sys.stderr)
        print(f"(see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Appends ``(default: ...)`` to each option's help unless the help already names it."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if "default" in text or not action.option_strings or action.default is argparse.SUPPRESS:
            return text
        if action.nargs == 0 and action.default is False:  # a flag
            return f"{text} (default: off)"
        return f"{text} (default: %(default)s)"


class AtLeast(argparse.Action):
    """Stores a number after checking it against ``least`` (>=) or ``above`` (>).

    The error names the flag and the value as typed: ``--num-envs=0: expected an integer >= 1``.
    """

    def __init__(
        self,
        option_strings: list[str],
        dest: str,
        *,
        least: float | None = None,
        above: float | None = None,
        **kwargs: Any,
    ) -> None:
        if (least is None) == (above is None):
            raise ValueError(f"AtLeast({dest!r}): give exactly one of least= and above=")
        super().__init__(option_strings, dest, **kwargs)
        self.least, self.above = least, above

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        value: Any,
        option_string: str | None = None,
    ) -> None:
        kind = "an integer" if self.type is int else "a number"
        if self.least is not None and not value >= self.least:
            parser.error(f"{option_string}={value}: expected {kind} >= {self.least}")
        if self.above is not None and not value > self.above:
            parser.error(f"{option_string}={value}: expected {kind} > {self.above}")
        setattr(namespace, self.dest, value)


class OneOf(argparse.Action):
    """Stores a value after checking it against a fixed set, each choice with its meaning.

    The error names the flag, the value as typed and what each choice means:
    ``--policy-lag=2: expected 0 (synchronous PPO) or 1 (update overlapped ...)``.
    """

    def __init__(
        self, option_strings: list[str], dest: str, *, meanings: dict[Any, str], **kwargs: Any
    ) -> None:
        kwargs.setdefault("metavar", "{" + ",".join(map(str, meanings)) + "}")
        super().__init__(option_strings, dest, **kwargs)
        self.meanings = meanings

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        value: Any,
        option_string: str | None = None,
    ) -> None:
        if value not in self.meanings:
            *rest, last = [f"{choice} ({meaning})" for choice, meaning in self.meanings.items()]
            expected = f"{', '.join(rest)} or {last}" if rest else last
            parser.error(f"{option_string}={value}: expected {expected}")
        setattr(namespace, self.dest, value)


def installed_version() -> str:
    """chronogym's version as installed (its package metadata)."""
    try:
        return version("chronogym")
    except PackageNotFoundError:
        return "unknown (not installed; run `pip install -e .`)"


def add_command(sub: Any, name: str) -> Parser:
    """The parser of subcommand ``name``: it shows defaults and takes ``--debug``."""
    summary, description = COMMAND_TEXTS[name]
    parser = sub.add_parser(
        name, help=summary, description=description, formatter_class=HelpFormatter
    )
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    return parser


def add_int(parser: Parser, flag: str, default: int | None, text: str, least: int = 1) -> None:
    """An integer option that must be ``>= least``."""
    parser.add_argument(flag, type=int, default=default, action=AtLeast, least=least, help=text)


def add_ray_options(parser: Parser) -> None:
    """Where the Ray workers run: ``--envs-per-worker`` and ``--address``."""
    add_int(parser, "--envs-per-worker", None, ENVS_PER_WORKER_HELP)
    parser.add_argument("--address", help=ADDRESS_HELP)


def add_quadruped_world(parser: Parser) -> None:
    """``--terrain`` and ``--engine`` of the Go1."""
    parser.add_argument(
        "--terrain", default="rigid", choices=QUADRUPED_TERRAINS, help=QUADRUPED_TERRAIN_HELP
    )
    parser.add_argument(
        "--engine", default="mujoco", choices=QUADRUPED_ENGINES, help=QUADRUPED_ENGINE_HELP
    )


def add_demo(sub: Any) -> None:
    demo = add_command(sub, "demo")
    add_int(demo, "--num-envs", 8, "cart-poles stepped in parallel")
    add_int(demo, "--steps", 1000, "vector steps to run")
    add_int(demo, "--ticks", 200, "physics ticks per env step (20 ms of control)")
    add_int(demo, "--cheap-ticks", 10, "also time a workload of this many ticks (0: skip)", least=0)
    add_int(demo, "--seed", 0, "seed of the envs and the policy noise", least=0)
    demo.add_argument(
        "--noise", type=float, default=1.5, action=AtLeast, least=0, help="policy noise std"
    )
    add_ray_options(demo)


def add_optimize(sub: Any) -> None:
    opt = add_command(sub, "optimize")
    opt.add_argument("problem", choices=["lander"], help="the design problem")
    add_int(opt, "--workers", 2, "trials run in parallel")
    add_int(opt, "--trials", 40, "finished trials wanted in the study")
    opt.add_argument(
        "--terrain", default="rigid", choices=list(LANDER_TERRAINS), help="landing ground"
    )
    opt.add_argument(
        "--storage",
        default=DEFAULT_STORAGE,
        help="Optuna storage URL: sqlite:///FILE.db, journal:FILE.log or an RDB URL",
    )
    opt.add_argument(
        "--engine",
        default="mujoco",
        choices=list(LANDER_ENGINES),
        help="physics engine (mujoco: rigid, rough, soil; chrono: rigid, scm; needs PyChrono)",
    )
    opt.add_argument("--study", help="study name (default: lander-TERRAIN, +-chrono for Chrono)")
    add_int(opt, "--seed", 0, "seed of the TPE sampler", least=0)
    add_int(opt, "--startup-trials", 10, "random trials before TPE", least=0)
    opt.add_argument(
        "--no-constant-liar",
        action="store_true",
        help="let parallel TPE suggestions ignore the trials still running",
    )
    opt.add_argument(
        "--backend",
        default="ray",
        choices=["ray", "serial"],
        help="ray: trials on Ray workers; serial: one trial at a time here (--workers 1)",
    )
    opt.add_argument("--address", help=ADDRESS_HELP)


def add_train(sub: Any) -> None:
    tr = add_command(sub, "train")
    tr.add_argument("problem", choices=["quadruped"], help="the task to learn")
    add_int(tr, "--num-envs", 32, "envs collecting data")
    tr.add_argument("--backend", default="ray", choices=["ray", "serial"], help=BACKEND_HELP)
    add_int(tr, "--iterations", None, "PPO iterations to run (default: until --minutes are spent)")
    tr.add_argument(
        "--minutes",
        type=float,
        action=AtLeast,
        above=0,
        help="wall-clock budget in minutes (default: until --iterations are done)",
    )
    tr.add_argument("--out", default="runs/quadruped", help="folder of logs, CSV and checkpoints")
    tr.add_argument("--resume", help="checkpoint to continue from (default: a fresh policy)")
    add_quadruped_world(tr)
    tr.add_argument("--finetune", action="store_true", help="conservative PPO (paper's transfer)")
    tr.add_argument(
        "--observe-base-lin-vel",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the policy also observes the base's linear velocity: 48 observations, as "
        "legged_gym's and Isaac Lab's (--no-observe-base-lin-vel: the paper's 45) "
        "(default: on, or what the --resume checkpoint was trained with)",
    )
    tr.add_argument(
        "--fine-tracking-weight",
        type=float,
        default=None,
        action=AtLeast,
        least=0,
        help="reward weight of the narrow linear-velocity tracking kernel, exp(-error^2/0.05), "
        "beside the paper's exp(-error^2/0.25); 0 trains on the paper's reward (default: 1.0)",
    )
    add_int(tr, "--seed", 0, "seed of the envs and the learner", least=0)
    add_int(tr, "--torch-threads", 1, "torch CPU threads (learner)")
    tr.add_argument(
        "--driver-worker",
        action="store_true",
        help="the training process steps one Ray worker's envs itself: faster on small "
        "machines, but an env that crashes its process ends the run (Ray backend only)",
    )
    tr.add_argument(
        "--policy-lag",
        type=int,
        default=0,
        action=OneOf,
        meanings={0: "synchronous PPO", 1: "update overlapped with the next rollout"},
        help="0 (default): synchronous PPO, the update on every core while the simulations "
        "wait; 1: run each update while the next rollout is collected, one update stale",
    )
    add_int(
        tr,
        "--update-threads",
        None,
        "torch threads of the synchronous update (default: this machine's CPUs, at most 8)",
    )
    tr.add_argument(
        "--env-errors",
        choices=("restart", "raise"),
        default="restart",
        help="what an env's Python exception does: 'restart' (default, for long unattended "
        "runs) rebuilds the env and truncates its episode, and stops the run if it fails again "
        "right after the rebuild; 'raise' stops at the first, to debug a task",
    )
    add_int(
        tr,
        "--eval-episodes",
        5,
        "episodes per group of the walking criterion (its commands and its command switch) "
        "that judge each saved checkpoint for best.pt; 5 is the criterion's own (0: none)",
        least=0,
    )
    add_ray_options(tr)


def add_play(sub: Any) -> None:
    play = add_command(sub, "play")
    play.add_argument("problem", choices=["quadruped"], help="the task the policy learned")
    play.add_argument("checkpoint", help="a checkpoint that `chronogym train` wrote (.pt)")
    play.add_argument(
        "--video",
        help="MP4 to write (.gif: an animation, .png: a film strip) (default: no video)",
    )
    play.add_argument(
        "--video-seconds",
        type=float,
        default=5.0,
        action=AtLeast,
        above=0,
        help="seconds recorded per command",
    )
    add_int(play, "--episodes", 1, "episodes per command")
    play.add_argument(
        "--command",
        nargs=3,
        type=float,
        action="append",
        metavar=("VX", "VY", "WZ"),
        help="a command to evaluate (repeatable; default: a standard set)",
    )
    add_int(play, "--steps", None, "episode length in steps (default: the task's, 1000)")
    play.add_argument(
        "--push",
        action="store_true",
        help="kick the base every --push-interval s by up to --push-velocity m/s per axis",
    )
    play.add_argument(
        "--push-velocity", type=float, default=1.0, action=AtLeast, above=0, help="m/s"
    )
    play.add_argument(
        "--push-interval", type=float, default=5.0, action=AtLeast, above=0, help="seconds"
    )
    play.add_argument(
        "--friction",
        nargs=2,
        type=float,
        metavar=("LO", "HI"),
        help="draw the foot-ground friction of each episode uniformly from [LO, HI] "
        "(default: the model's)",
    )
    play.add_argument(
        "--check-walking",
        action="store_true",
        help="run exactly the walking criterion's episodes (its 6 commands and its command "
        "switch, 5 episodes each, 20 s) and say whether the policy walks, by v2 and by v1",
    )
    play.add_argument("--traces", help="save every episode's velocity trace to this .npz")
    play.add_argument(
        "--step-response",
        help="draw vx, vy and the yaw rate against time for every command into this PNG",
    )
    add_quadruped_world(play)
    add_int(play, "--seed", 0, "seed of the episodes", least=0)


def add_envs(sub: Any) -> None:
    envs = add_command(sub, "envs")
    envs.add_argument(
        "env_id", nargs="?", metavar="ID", help="an id to describe, e.g. chronogym/CartPole-v0"
    )


def add_bench(sub: Any) -> None:
    bench = add_command(sub, "bench")
    bench.add_argument("env_id", metavar="ID", help="a registered id, e.g. chronogym/CartPole-v0")
    bench.add_argument(
        "--seconds",
        type=float,
        default=3.0,
        action=AtLeast,
        above=0,
        help="seconds of timing per setting",
    )
    add_int(bench, "--max-workers", 16, "most Ray workers timed (the fit's largest W)")
    add_int(bench, "--cores", None, "cores to plan for (default: the Ray cluster's CPUs)")
    bench.add_argument(
        "--target",
        type=float,
        default=0.8,
        action=AtLeast,
        above=0,
        help="parallel efficiency the recommendation keeps",
    )
    bench.add_argument(
        "--env-kwargs",
        default="{}",
        metavar="JSON",
        help="keyword arguments of gymnasium.make, as a JSON object, e.g. '{\"k\": 10}'",
    )
    bench.add_argument(
        "--no-check",
        action="store_true",
        help="skip the last run, on the env itself, that checks the model",
    )
    bench.add_argument("--address", help=ADDRESS_HELP)
    bench.add_argument(
        "--transport",
        choices=["socket", "actor", "fork"],
        help="RayVectorEnv's transport to time (default: its default, socket)",
    )


def build_parser() -> Parser:
    """The parser of ``chronogym``; ``args.subcommand`` names the subcommand chosen."""
    parser = Parser(
        prog="chronogym",
        description="High-fidelity simulations as Gymnasium environments, in parallel on Ray.",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"chronogym {installed_version()}")
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    sub = parser.add_subparsers(
        dest="subcommand",
        required=True,
        metavar="COMMAND",
        help="one of these (`chronogym COMMAND --help` shows its options):",
    )
    for add in (add_demo, add_optimize, add_train, add_play, add_envs, add_bench):
        add(sub)
    return parser
