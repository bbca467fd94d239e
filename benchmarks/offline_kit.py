"""A tarball of the packages a benchmark needs, for a machine that cannot reach a package index.

Some machines worth measuring on have no network: an air-gapped cluster node, a lent test
machine with many cores. They often hold a Python with NumPy, Numba and the like, but not
MuJoCo, Gymnasium or EnvPool. This script downloads those wheels here, for the other machine's
Python version and platform, unpacks them into one folder and packs it, small enough to carry:

    python -m benchmarks.offline_kit --python 3.12 --out .kit/site.tgz

and there, from a copy of this repository (no install; ``src`` on the path):

    mkdir -p /tmp/site && tar xzf .kit/site.tgz -C /tmp/site
    export PYTHONPATH=/tmp/site:src
    bash benchmarks/vector/many_cores.sh OUT_DIR

What it holds: each of ``--packages`` at the version installed here (or the pin given), with no
dependencies beyond those named. EnvPool's wheel (~53 MB) and its assets (~62 MB) ship every
suite; the kit keeps only the compiled suites of ``--envpool-suites`` (default the Gymnasium
MuJoCo tasks, ~12 MB) and their assets, which is all ``peers.py`` and ``cores.py`` run. Ray is
not in it: its wheel alone is ~80 MB. Without Ray, chronogym's ``transport="fork"`` (no Ray at
all on one machine), Gymnasium's vector envs and EnvPool run; the paths that need Ray actors are
skipped by the benchmarks with a note.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from importlib import metadata
from pathlib import Path

#: Packages a MuJoCo benchmark needs beyond a scientific Python (NumPy, Numba, tqdm, ...).
DEFAULT_PACKAGES = (
    "mujoco",
    "mujoco-core",
    "glfw",
    "pyopengl",
    "gymnasium",
    "farama-notifications",
    "envpool",
    "envpool-assets",
    "dm-env",
    "dm-tree",
    "optree",
)
#: Platform tags pip may take a binary wheel for (x86-64 Linux, newest first).
PLATFORMS = (
    "manylinux_2_28_x86_64",
    "manylinux_2_27_x86_64",
    "manylinux_2_24_x86_64",
    "manylinux_2_17_x86_64",
    "manylinux2014_x86_64",
    "manylinux1_x86_64",
)
#: EnvPool's compiled suites are ``envpool/<folder>/<suite>_envpool.so``; assets by suite.
ENVPOOL_ASSETS = {"mujoco_gym": "mujoco/assets_gym"}


def pinned(name: str) -> str:
    """``name==version`` at the version installed here; ``name`` as is if it holds a pin or
    is not installed."""
    if any(sign in name for sign in "=<>"):
        return name
    try:
        return f"{name}=={metadata.version(name)}"
    except metadata.PackageNotFoundError:
        return name


def download(requirements: list[str], python: str, folder: Path) -> list[Path]:
    """Binary wheels of ``requirements`` for CPython ``python`` on x86-64 Linux, no deps."""
    command = [sys.executable, "-m", "pip", "download", "-q", "--no-deps"]
    command += ["--only-binary=:all:", "--python-version", python, "--implementation", "cp"]
    for tag in PLATFORMS:
        command += ["--platform", tag]
    subprocess.run([*command, "-d", str(folder), *requirements], check=True)
    return sorted(folder.glob("*.whl"))


def trim_envpool(site: Path, suites: list[str]) -> list[str]:
    """Delete EnvPool's compiled suites not in ``suites`` and every asset folder but theirs;
    the Python registration files stay (``envpool.make`` loads a suite's library only when
    asked for one of its tasks). Returns the paths removed, relative to ``site``."""
    removed: list[str] = []
    keep = {f"{suite}_envpool.so" for suite in suites}
    package = site / "envpool"
    for library in sorted(package.rglob("*_envpool.so")):
        if library.name not in keep:
            library.unlink()
            removed.append(str(library.relative_to(site)))
    drop_registrations(package, {Path(path).stem for path in removed})
    for bulky in (package / "vizdoom" / "bin", package / "jumanji" / "assets"):
        if bulky.exists():
            shutil.rmtree(bulky)
            removed.append(str(bulky.relative_to(site)))
    assets = site / "envpool_assets"
    wanted = {assets / ENVPOOL_ASSETS[s] for s in suites if s in ENVPOOL_ASSETS}
    if assets.is_dir():
        for path in sorted(assets.rglob("*"), key=lambda p: len(p.parts)):
            if not path.is_dir() or not path.exists():
                continue
            inside = any(path == w or w in path.parents for w in wanted)
            above = any(path in w.parents for w in wanted)
            if not inside and not above:
                shutil.rmtree(path)
                removed.append(str(path.relative_to(site)))
    return removed


def drop_registrations(package: Path, libraries: set[str]) -> None:
    """Rewrite ``envpool/entry.py`` without the registrations whose suite package imports one of
    the removed ``libraries`` (module stems) on import."""
    entry = package / "entry.py"
    if not entry.exists():
        return
    kept = []
    for line in entry.read_text().splitlines():
        module = line.split()[1] if line.startswith("import envpool.") else None
        if module:
            init = package.parent.joinpath(*module.split(".")[:-1], "__init__.py")
            source = init.read_text() if init.exists() else ""
            if any(library in source for library in libraries):
                continue
        kept.append(line)
    entry.write_text("\n".join(kept) + "\n")


def build_kit(
    packages: list[str], python: str, suites: list[str], out: Path, wheels: Path | None = None
) -> dict[str, object]:
    """Download (or take from ``wheels``), unpack, trim EnvPool, pack ``out`` (.tgz)."""
    with tempfile.TemporaryDirectory() as tmp:
        site = Path(tmp) / "site"
        site.mkdir()
        if wheels is None:
            wheels = Path(tmp) / "wheels"
            wheels.mkdir()
            download([pinned(p) for p in packages], python, wheels)
        files = sorted(wheels.glob("*.whl"))
        if not files:
            raise ValueError(f"no wheels in {wheels}: expected the downloaded packages")
        for wheel in files:
            with zipfile.ZipFile(wheel) as archive:
                archive.extractall(site)
        removed = trim_envpool(site, suites)
        out.parent.mkdir(parents=True, exist_ok=True)
        with tarfile.open(out, "w:gz") as tar:
            for path in sorted(site.iterdir()):
                tar.add(path, arcname=path.name)
    return {"wheels": [w.name for w in files], "removed": removed, "bytes": out.stat().st_size}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", default="3.12", help="the other machine's Python (X.Y)")
    parser.add_argument(
        "--packages",
        nargs="+",
        default=list(DEFAULT_PACKAGES),
        help="names (at the version installed here) or pins; default: MuJoCo, Gymnasium, EnvPool",
    )
    parser.add_argument(
        "--envpool-suites",
        nargs="+",
        default=["mujoco_gym"],
        help="EnvPool suites kept (default: mujoco_gym, Gymnasium's MuJoCo tasks)",
    )
    parser.add_argument("--wheels", type=Path, help="take the wheels from this folder instead")
    parser.add_argument("--out", type=Path, default=Path(".kit/site.tgz"), help="the tarball")
    args = parser.parse_args(argv)
    if not all(part.isdigit() for part in args.python.split(".")) or args.python.count(".") != 1:
        parser.error(f"--python {args.python!r}: expected a version X.Y, e.g. 3.12")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    kit = build_kit(args.packages, args.python, args.envpool_suites, args.out, args.wheels)
    print(f"{len(kit['wheels'])} wheels: {', '.join(kit['wheels'])}")
    print(f"EnvPool trimmed: {len(kit['removed'])} suites and asset folders left out")
    print(f"wrote {args.out} ({kit['bytes'] / 2**20:.1f} MiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
