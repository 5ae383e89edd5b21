"""The slim core: the wheel holds the envs and the zoo's NumPy actors, never an agent's full
model (the SB3/SBX ``.zip`` that ``rehabbot zoo fetch`` gets), whatever lies in the source
folder; pyproject.toml's package data cannot take one in. Sizes are measured by
``benchmarks/packaging/install_size.py``, not asserted here."""

from __future__ import annotations

import fnmatch
import importlib.util
import shutil
import sys
import zipfile
from pathlib import Path

import pytest

from benchmarks.packaging.install_size import build_wheel

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "rehabbot" / "zoo"
# Where a full model may lie in a source folder: a zoo exported with --full, a copy.
FULL_MODEL_PATHS = ("rehab-knee-v2/sac.zip", "sac.zip", "rehab-hip-v2/extra/td3.zip")


def _pyproject() -> dict:
    if sys.version_info >= (3, 11):
        import tomllib
    else:
        tomllib = pytest.importorskip("tomli")
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _matches(patterns: list[str], path: str) -> bool:
    # setuptools matches package-data globs with fnmatch against the path below the
    # package's folder, where "*" also crosses "/".
    return any(fnmatch.fnmatch(path, pattern) for pattern in patterns)


def test_package_data_cannot_take_a_full_model_in() -> None:
    setuptools = _pyproject()["tool"]["setuptools"]
    data = setuptools.get("package-data", {})
    zoo_patterns = data.get("rehabbot.zoo", [])
    assert _matches(zoo_patterns, "rehab-knee-v2/sac.npz")  # the actors are package data
    for path in FULL_MODEL_PATHS:
        assert not _matches(zoo_patterns, path), path
        # "rehabbot" holds the zoo folder; "*" and "" reach every package.
        for package, below in (("rehabbot", f"zoo/{path}"), ("*", path), ("", path)):
            assert not _matches(data.get(package, []), below), (package, below)
        # ... and the exclusion removes one whatever includes it (include-package-data).
        assert _matches(setuptools["exclude-package-data"]["rehabbot.zoo"], path), path
    assert not (ROOT / "MANIFEST.in").exists() or ".zip" not in (ROOT / "MANIFEST.in").read_text()


def test_no_full_model_is_tracked_in_the_zoo() -> None:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not in a git clone")
    import subprocess

    tracked = subprocess.run(["git", "-C", str(ROOT), "ls-files", "rehabbot/zoo"], check=True,
                             capture_output=True, text=True).stdout.split()
    assert [name for name in tracked if name.endswith(".npz")]
    # the actors, and the held-out figures `rehabbot zoo list` shows
    assert [name for name in tracked if not name.endswith((".npz", ".py", "/heldout.json"))] \
        == []


@pytest.mark.slow
def test_the_wheel_holds_the_actors_and_no_full_model(tmp_path: Path) -> None:
    """The wheel of a source folder where full models lie in the zoo (as after
    ``rehabbot zoo export --full``): every NumPy actor and the settings files are in it, no
    ``.zip``."""
    if importlib.util.find_spec("setuptools") is None:
        pytest.skip("needs setuptools (the build backend) in this Python")
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, source / name)
    shutil.copytree(ROOT / "rehabbot", source / "rehabbot",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.zip"))
    for path in FULL_MODEL_PATHS:
        decoy = source / "rehabbot" / "zoo" / path
        decoy.parent.mkdir(parents=True, exist_ok=True)
        decoy.write_bytes(b"PK\x05\x06" + bytes(18))  # an empty zip archive
    with zipfile.ZipFile(build_wheel(source, tmp_path / "dist")) as wheel:
        names = set(wheel.namelist())
    actors = {f"rehabbot/zoo/{p.parent.name}/{p.name}" for p in ZOO.glob("*/*.npz")}
    assert actors and actors <= names
    assert "rehabbot/rl/hyperparams/sac.yml" in names
    assert [name for name in names if name.endswith(".zip")] == []
