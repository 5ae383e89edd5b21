"""The machine a timing ran on, in one line for a results page (absolute rates depend on it;
the ratios a performance page reports are measured in the same run)."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name (Linux ``/proc/cpuinfo``), else :func:`platform.processor`."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(errors="replace").splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine() or "unknown CPU"


def describe_machine() -> str:
    """The CPU, its logical CPUs (and how many this process may use), the OS, Python, MuJoCo
    and ``OMP_NUM_THREADS``, in one line."""
    import mujoco

    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (f"{cpu_model()}, {os.cpu_count()} logical CPUs ({usable} usable), "
            f"{platform.system()} {platform.machine()}, Python {platform.python_version()}, "
            f"MuJoCo {mujoco.__version__}, "
            f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")
