"""The size of the slim core: the wheel, what a core install (no extras) puts on disk, and the
repository's tracked tree.

Usage::

    python benchmarks/packaging/install_size.py [--ref REF] [--no-deps] [--json FILE]

1. The source: the working tree's files that git tracks or would track (``git ls-files
   --cached --others --exclude-standard``), or with ``--ref`` the tree of a commit (``git
   archive REF``), copied to a temporary folder, so the build leaves nothing here.
2. The wheel: ``pip wheel --no-deps --no-build-isolation`` (the running Python's setuptools)
   of that copy; its size, its files, the zoo's NumPy actors (``.npz``) and full models
   (``.zip``) in it.
3. The install: a fresh venv (``python -m venv``, this Python) and ``pip install WHEEL``,
   core dependencies only (mujoco, gymnasium, numpy: from the package index), then
   ``import rehabbot.zoo`` and one action of a zoo agent in it. Reported: the installed size
   of rehabbot (its package folder and ``.dist-info``, byte-compiled files included: what is
   on disk) and of the venv's whole ``site-packages``. ``--no-deps`` installs rehabbot alone
   (offline; no smoke run, no ``site-packages`` total).
4. The tracked tree: the sum of the sizes of ``git ls-files`` (``git ls-tree -r -l REF`` with
   ``--ref``).

Sizes are in bytes and MB (10^6 bytes); ``--json`` writes them to FILE.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import venv
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPOSITORY = Path(__file__).resolve().parents[2]
SMOKE = ("import numpy as np, rehabbot.zoo; agent = rehabbot.zoo.load('rehab-knee-v2', 'sac'); "
         "print(agent.predict(np.zeros(agent.observation_space.shape, np.float32))[0].shape)")


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(REPOSITORY), *args], check=True,
                          capture_output=True, text=True).stdout


def source_files(ref: str | None) -> list[str]:
    """The files of the source: those git tracks or would track in the working tree, or
    those of ``ref``'s tree."""
    if ref is not None:
        return _git("ls-tree", "-r", "--name-only", "-z", ref).split("\0")[:-1]
    listed = _git("ls-files", "-z", "--cached", "--others", "--exclude-standard")
    return [name for name in listed.split("\0")[:-1] if (REPOSITORY / name).is_file()]


def tracked_tree_bytes(ref: str | None) -> int:
    """The sum of the sizes of the files git tracks (in the working tree, or in ``ref``)."""
    if ref is not None:
        total = 0
        for line in _git("ls-tree", "-r", "-l", ref).splitlines():
            size = line.split()[3]
            total += int(size) if size.isdigit() else 0  # "-" for a submodule
        return total
    names = _git("ls-files", "-z").split("\0")[:-1]
    return sum((REPOSITORY / name).stat().st_size for name in names
               if (REPOSITORY / name).is_file())


def copy_source(ref: str | None, destination: Path) -> Path:
    """The source (:func:`source_files`) copied into ``destination``."""
    destination.mkdir(parents=True, exist_ok=True)
    if ref is not None:
        archive = subprocess.run(["git", "-C", str(REPOSITORY), "archive", ref],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(destination)], input=archive, check=True)
        return destination
    for name in source_files(None):
        target = destination / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPOSITORY / name, target)
    return destination


def build_wheel(source: Path, out_dir: Path) -> Path:
    """``pip wheel`` of ``source`` into ``out_dir`` (no dependencies, no build isolation:
    the running Python's setuptools builds it); the wheel's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "--no-cache-dir", "--quiet", "--wheel-dir", str(out_dir), str(source)],
                   check=True, capture_output=True, text=True)
    wheels = sorted(out_dir.glob("rehabbot-*.whl"))
    if len(wheels) != 1:
        raise RuntimeError(f"expected one rehabbot wheel in {out_dir}, found {wheels}")
    return wheels[0]


def wheel_contents(wheel: Path) -> dict[str, Any]:
    """The wheel's size and what it holds: files, the zoo's actors and full models."""
    with zipfile.ZipFile(wheel) as archive:
        infos = archive.infolist()
    zoo = [info for info in infos if info.filename.startswith("rehabbot/zoo/")]
    actors = [info for info in zoo if info.filename.endswith(".npz")]
    models = [info for info in infos if info.filename.endswith(".zip")]
    return {"wheel_bytes": wheel.stat().st_size, "files": len(infos),
            "uncompressed_bytes": sum(info.file_size for info in infos),
            "zoo_actors": len(actors), "zoo_actor_bytes": sum(i.file_size for i in actors),
            "full_models": len(models), "full_model_bytes": sum(i.file_size for i in models)}


def folder_bytes(folder: Path) -> int:
    return sum(path.stat().st_size for path in folder.rglob("*")
               if path.is_file() and not path.is_symlink())


def install(wheel: Path, venv_dir: Path, deps: bool) -> dict[str, Any]:
    """Install ``wheel`` into a fresh venv; the installed sizes (and the smoke run's output
    with its dependencies)."""
    venv.EnvBuilder(with_pip=True, clear=True).create(venv_dir)
    python = venv_dir / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
    pip = [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
           "--no-cache-dir"]
    subprocess.run([*pip, *([] if deps else ["--no-deps"]), str(wheel)], check=True,
                   capture_output=True, text=True)
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; "
                                "print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    rehabbot = folder_bytes(site / "rehabbot") + sum(
        folder_bytes(info) for info in site.glob("rehabbot-*.dist-info"))
    result: dict[str, Any] = {"installed_rehabbot_bytes": rehabbot,
                              "installed_full_models": len(list((site / "rehabbot").rglob(
                                  "*.zip")))}
    if deps:
        smoke = subprocess.run([str(python), "-c", SMOKE], capture_output=True, text=True,
                               cwd=venv_dir, env={**os.environ, "PYTHONPATH": ""})
        result.update(site_packages_bytes=folder_bytes(site),
                      smoke_ok=smoke.returncode == 0,
                      smoke_output=(smoke.stdout + smoke.stderr).strip()[-500:])
    return result


def measure(ref: str | None, deps: bool) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="rehabbot-size-") as tmp:
        work = Path(tmp)
        wheel = build_wheel(copy_source(ref, work / "source"), work / "dist")
        report = {"source": ref or "working tree", "command": " ".join(sys.argv),
                  "tracked_tree_bytes": tracked_tree_bytes(ref), **wheel_contents(wheel),
                  **install(wheel, work / "venv", deps)}
    return report


def _mb(value: int) -> str:
    return f"{value / 1e6:.1f} MB"


def describe(report: dict[str, Any]) -> str:
    lines = [f"source: {report['source']}",
             f"tracked tree (git ls-files): {_mb(report['tracked_tree_bytes'])}",
             f"wheel: {_mb(report['wheel_bytes'])} ({report['files']} files, "
             f"{_mb(report['uncompressed_bytes'])} uncompressed)",
             f"  zoo actors (.npz): {report['zoo_actors']}, {_mb(report['zoo_actor_bytes'])}",
             f"  full models (.zip): {report['full_models']}, "
             f"{_mb(report['full_model_bytes'])}",
             f"installed rehabbot (core, no extras): {_mb(report['installed_rehabbot_bytes'])}"]
    if "site_packages_bytes" in report:
        lines.append(f"site-packages of the core venv (rehabbot, mujoco, gymnasium, numpy...): "
                     f"{_mb(report['site_packages_bytes'])}")
        lines.append(f"a zoo agent acts in it: {'yes' if report['smoke_ok'] else 'NO'} "
                     f"({report['smoke_output']})")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ref", help="measure this commit's tree instead of the working tree")
    parser.add_argument("--no-deps", action="store_true",
                        help="install rehabbot alone (offline; no smoke run)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the numbers here")
    args = parser.parse_args(argv)
    report = measure(args.ref, deps=not args.no_deps)
    print(describe(report))
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    return 0 if report.get("smoke_ok", True) else 1


if __name__ == "__main__":
    sys.exit(main())
