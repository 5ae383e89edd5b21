"""Run the ``rehabbot`` command as on a core install (``pip install rehabbot``: the
dependencies of ``[project] dependencies`` and nothing of the extras), in this venv, which
holds every extra: a subprocess whose import system hides every module that only a
distribution outside the core brings.

:func:`hidden_names` works out what to hide from ``pyproject.toml`` and the installed
distributions' metadata (the core's requirements, followed transitively); :func:`run_core`
starts ``python -c`` with :data:`HIDE_SOURCE`, which replaces the path finder of
``sys.meta_path`` by one that does not find the hidden modules (``import x`` raises
``ModuleNotFoundError``, ``importlib.util.find_spec(x)`` is None, and
``importlib.metadata`` does not list their distributions), then runs
``rehabbot.cli.main``. Used by tests/test_cli_session.py.
"""

from __future__ import annotations

import functools
import importlib.metadata as metadata
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]

# What the subprocess runs first: argv[1] is a JSON object {"modules": [...], "dists": [...]}.
HIDE_SOURCE = """
import importlib.machinery, json, re, sys
hidden = json.loads(sys.argv[1])
modules, dists = set(hidden["modules"]), set(hidden["dists"])
del sys.argv[1]

def _is_hidden(fullname):
    parts = fullname.split(".")
    return any(".".join(parts[:i]) in modules for i in range(1, len(parts) + 1))

def _name(dist):
    return re.sub(r"[-_.]+", "-", (dist.metadata["Name"] or "")).lower()

class CoreOnlyPathFinder:
    @classmethod
    def find_spec(cls, fullname, path=None, target=None):
        if _is_hidden(fullname):
            return None
        return importlib.machinery.PathFinder.find_spec(fullname, path, target)

    @classmethod
    def find_distributions(cls, *args, **kwargs):
        return (d for d in importlib.machinery.PathFinder.find_distributions(*args, **kwargs)
                if _name(d) not in dists)

    @classmethod
    def invalidate_caches(cls):
        importlib.machinery.PathFinder.invalidate_caches()

sys.meta_path[:] = [CoreOnlyPathFinder if f is importlib.machinery.PathFinder else f
                    for f in sys.meta_path]
for name in [m for m in sys.modules if _is_hidden(m)]:
    del sys.modules[name]
"""

RUN_CLI_SOURCE = HIDE_SOURCE + """
from rehabbot.cli import main
code = main(sys.argv[1:])
heavy = sorted(m for m in ("mujoco", "rehabbot.sim.scene", "rehabbot.envs.rehab_env")
               if m in sys.modules)
print("IMPORTED " + json.dumps(heavy), file=sys.stderr)
raise SystemExit(code)
"""


def normalized(name: str) -> str:
    """A distribution name as pip compares them (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_names(requirements: Iterable[str]) -> list[str]:
    from packaging.requirements import Requirement

    names = []
    for text in requirements:
        requirement = Requirement(text)
        marker = requirement.marker
        if marker is not None and not marker.evaluate({"extra": ""}):
            continue  # an extra's requirement, or another platform's
        names.append(normalized(requirement.name))
    return names


@functools.cache
def core_distributions() -> frozenset[str]:
    """The distributions a core install holds: ``[project] dependencies`` of pyproject.toml
    and, transitively, what they require (normalized names)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = _requirement_names(project["dependencies"])
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            todo += _requirement_names(metadata.requires(name) or [])
        except metadata.PackageNotFoundError:
            continue
    return frozenset(seen)


@functools.cache
def hidden_names() -> dict[str, list[str]]:
    """``{"modules": [...], "dists": [...]}``: the distributions installed here that a core
    install lacks, and the modules that only they bring (top-level names, and the
    subpackages they add to a package of the core, such as ``mujoco.mjx``)."""
    core = core_distributions() | {"rehabbot"}
    core_top: set[str] = set()
    extra: dict[str, set[str]] = {}
    for dist in metadata.distributions():
        name = normalized(dist.metadata["Name"] or "")
        tops: set[str] = set()
        for file in dist.files or ():
            parts = file.parts
            if not parts or parts[0].endswith((".dist-info", ".egg-info", ".data")) \
                    or parts[0] in ("..", "__pycache__", "bin"):
                continue
            if len(parts) == 1:
                if file.suffix in (".py", ".so", ".pyd"):
                    tops.add(parts[0].split(".")[0])
                continue
            tops.add(parts[0])
            if len(parts) > 2 or parts[1].endswith(".py"):
                tops.add(f"{parts[0]}.{parts[1].removesuffix('.py')}")
        if name in core:
            core_top |= {top for top in tops if "." not in top}
        else:
            extra[name] = tops
    modules: set[str] = set()
    for tops in extra.values():
        for top in tops:
            head = top.split(".")[0]
            if "." not in top and top not in core_top and top.isidentifier():
                modules.add(top)
            elif "." in top and head in core_top and top.split(".")[1].isidentifier():
                modules.add(top)  # a subpackage added to a core package: mujoco.mjx
    modules -= set(sys.stdlib_module_names)
    return {"modules": sorted(modules), "dists": sorted(extra)}


def core_env(**extra: str) -> dict[str, str]:
    """The environment of a subprocess: this worktree first on ``PYTHONPATH``, headless GL,
    one thread."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(
        os.pathsep)
    env.setdefault("MUJOCO_GL", "egl")
    env["OMP_NUM_THREADS"] = "1"
    env.update(extra)
    return env


def run_core(argv: Sequence[str], cwd: Path, *, hide: dict[str, list[str]] | None = None,
             timeout_s: float = 300) -> subprocess.CompletedProcess:
    """``rehabbot ARGV`` in ``cwd`` as on a core install (``hide``: what to hide instead of
    :func:`hidden_names`). Its stderr ends with a line ``IMPORTED [...]``: which of mujoco,
    the scene builder and the env class the command imported."""
    hidden = hidden_names() if hide is None else hide
    return subprocess.run([sys.executable, "-c", RUN_CLI_SOURCE, json.dumps(hidden), *argv],
                          cwd=cwd, env=core_env(), capture_output=True, text=True,
                          timeout=timeout_s)


def run_python_core(source: str, cwd: Path, *, timeout_s: float = 600
                    ) -> subprocess.CompletedProcess:
    """``python -c SOURCE`` as on a core install."""
    return subprocess.run([sys.executable, "-c", HIDE_SOURCE + source,
                           json.dumps(hidden_names())], cwd=cwd, env=core_env(),
                          capture_output=True, text=True, timeout=timeout_s)


def imported(stderr: str) -> list[str]:
    """The ``IMPORTED`` line of :func:`run_core`'s stderr."""
    line = [line for line in stderr.splitlines() if line.startswith("IMPORTED ")][-1]
    return json.loads(line.removeprefix("IMPORTED "))


def messages(stderr: str) -> list[str]:
    """stderr without the ``IMPORTED`` line."""
    return [line for line in stderr.splitlines() if not line.startswith("IMPORTED ")]
