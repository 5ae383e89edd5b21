"""Shared pytest configuration.

``MUJOCO_GL`` must be set before ``mujoco`` is first imported: MuJoCo picks its OpenGL
backend at import time. EGL renders offscreen without a display.

Plain ``pytest`` runs the fast selection (every test not marked ``slow``, under two minutes
on two cores); ``pytest --full`` (``make test``, CI) runs everything.
"""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--full", action="store_true",
                     help="run the whole suite, slow tests included (make test, CI)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--full"):
        return
    slow = [item for item in items if item.get_closest_marker("slow") is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if item.get_closest_marker("slow") is None]
