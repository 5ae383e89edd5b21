"""Shared pytest configuration.

``MUJOCO_GL`` must be set before ``mujoco`` is first imported: MuJoCo picks its OpenGL
backend at import time. EGL renders offscreen without a display.

Plain ``pytest`` runs the fast selection (every test not marked ``slow``, under two minutes
on two cores); ``pytest --full`` (``make test``, CI) runs everything.
"""

import os
import signal

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


@pytest.fixture
def python_sigint_handler():
    """Python's own SIGINT handler for the test (an earlier test in the same worker may have
    left another, such as SIG_IGN, to which a latched signal would be handed back)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
