"""The docs build with ``pip install ".[docs]"`` alone: what autodoc does about the libraries of
the other extras.

The API pages document every module, including :mod:`rehabbot.batch` and
:mod:`rehabbot.rl.rsl_vec_env`, which import ``[gpu]``'s JAX, Flax, Warp, MJX, rsl_rl and
TensorDict at their top. Where such a library is not installed, autodoc imports the module
with the library mocked (Sphinx's ``autodoc_mock_imports``): a mock stands for any value, so
that the module imports and its docstrings, signatures and annotations can be read. Installed
libraries are used as they are.

Two names of those libraries shape a documented class, and a mock would lose it: Flax's
``struct.dataclass`` makes :class:`rehabbot.batch.state.State` a dataclass (its fields are its
signature), and rsl_rl's ``VecEnv`` is the base of :class:`rehabbot.rl.rsl_vec_env.RslVecEnv`
(a mocked base would replace its signature with ``(*args, **kwargs)``). Where those libraries
are missing, the build puts small stand-ins for just those names in ``sys.modules``.

A new top-level import of another extra's library that is not listed here fails the strict
build in a docs-only venv (autodoc's "failed to import" warning), which is how CI finds it.
"""

from __future__ import annotations

import dataclasses
import importlib.machinery
import importlib.util
import sys
import types
from typing import Any

# The top-level imports of documented modules from libraries outside [docs] (and its [train]
# and [plot]): [gpu], [jax], [myo], [sweep], [video].
OPTIONAL_TOP_LEVEL_IMPORTS = (
    "jax", "flax", "optax", "warp", "mujoco.mjx", "rsl_rl", "tensordict", "myo_sim", "sbx",
    "ray", "imageio", "imageio_ffmpeg",
)


def is_missing(module: str) -> bool:
    """Whether ``module`` cannot be imported here (its package, or a parent, is absent)."""
    if module in sys.modules:
        return False
    try:
        return importlib.util.find_spec(module) is None
    except ModuleNotFoundError:  # a parent package is missing too
        return True


def _replace(self: Any, **updates: Any) -> Any:
    """Returns a new object replacing the specified fields with new values."""
    return dataclasses.replace(self, **updates)


def _flax_struct_dataclass(cls: type | None = None, **kwargs: Any) -> Any:
    """``flax.struct.dataclass``, as far as the docs see it: a frozen dataclass with Flax's
    ``replace`` method."""
    if cls is None:
        return lambda inner: _flax_struct_dataclass(inner, **kwargs)
    cls.replace = _replace
    return dataclasses.dataclass(frozen=True)(cls)


class _RslVecEnv:
    """rsl_rl's ``VecEnv`` (an abstract base class), as far as the docs see it."""


def _module(name: str, **attributes: Any) -> types.ModuleType:
    module = types.ModuleType(name, f"A docs-build stand-in for {name} (not installed).")
    module.__spec__ = importlib.machinery.ModuleSpec(name, loader=None)
    module.__dict__.update(attributes)
    return module


def install_stand_ins() -> list[str]:
    """Put the stand-ins of missing libraries in ``sys.modules``; return their names."""
    installed = []
    if is_missing("flax"):
        struct = _module("flax.struct", dataclass=_flax_struct_dataclass,
                         field=dataclasses.field)
        sys.modules.update({"flax": _module("flax", struct=struct), "flax.struct": struct})
        installed += ["flax", "flax.struct"]
    if is_missing("rsl_rl"):
        _RslVecEnv.__module__ = "rsl_rl.env"
        _RslVecEnv.__qualname__ = _RslVecEnv.__name__ = "VecEnv"
        env = _module("rsl_rl.env", VecEnv=_RslVecEnv)
        sys.modules.update({"rsl_rl": _module("rsl_rl", env=env), "rsl_rl.env": env})
        installed += ["rsl_rl", "rsl_rl.env"]
    return installed


def mocked_imports() -> list[str]:
    """The optional libraries to mock: those missing here, after the stand-ins went in."""
    install_stand_ins()
    return [module for module in OPTIONAL_TOP_LEVEL_IMPORTS if is_missing(module)]
