"""Where a result comes from: package versions, the git commit, the time."""

from __future__ import annotations

import functools
import platform
import re
import subprocess
from datetime import datetime, timezone
from pathlib import Path

VERSIONED_PACKAGES = (("stable_baselines3", "stable-baselines3"), ("torch", "torch"),
                      ("gymnasium", "gymnasium"), ("mujoco", "mujoco"), ("numpy", "numpy"))


@functools.cache
def package_versions() -> dict[str, str | None]:
    """Versions of Python and of the packages a result depends on (None: not installed)."""
    from rehabbot.common.version import VERSION

    versions: dict[str, str | None] = {"python": platform.python_version(),
                                       "rehabbot": VERSION}
    versions.update({key: distribution_version(dist) for key, dist in VERSIONED_PACKAGES})
    return versions


def distribution_version(distribution: str) -> str | None:
    """The installed version of the pip package ``distribution`` (None: not installed)."""
    from importlib import metadata

    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


@functools.cache
def git_commit() -> str | None:
    """HEAD of the rehabbot checkout, or None (installed copy, no git, timeout)."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        result = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                                capture_output=True, text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    commit = result.stdout.strip()
    return commit if result.returncode == 0 and re.fullmatch(r"[0-9a-f]{40,64}", commit) \
        else None


def now_iso() -> str:
    """The current UTC time, ISO 8601 to the second (``2026-11-23T10:00:00Z``)."""
    return datetime.now(timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")
