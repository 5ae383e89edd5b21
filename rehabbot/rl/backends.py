"""Which library trains a run: Stable-Baselines3 (PyTorch) or SBX (JAX).

=========== ============================================================================
``auto``    SBX when the ``sbx-rl`` package (and JAX) is installed, else Stable-Baselines3
``sb3``     Stable-Baselines3; TQC and CrossQ from sb3-contrib
``sbx``     SBX (Stable-Baselines-Jax): the same algorithms, jit-compiled; an error if it
            is not installed
=========== ============================================================================

Both write the same run folder and load through the same paths; the manifest records the
backend (``backend``) and its library's version (``backend_version``), and a resumed or
evaluated run uses the backend it was trained with. SBX runs its networks through JAX, so it
cannot use PyTorch policy classes or features extractors: :mod:`rehabbot.rl.sbx_settings`
translates a settings file and lists what it changed.
"""

from __future__ import annotations

import importlib.util

from rehabbot.common.extras import install_hint
from rehabbot.common.provenance import distribution_version
from rehabbot.rl.algorithms import (
    ALGO_CLASSES,
    ALGO_NAMES,
    BACKENDS,
    DISTRIBUTIONS,
    BackendUnavailableError,
    algo_class,
    check_algo,
    one_of,
)

BACKEND_CHOICES = ("auto", *BACKENDS)
DEFAULT_BACKEND = "auto"
# The libraries whose versions a run of each backend records (import name, distribution), the
# backend's own first.
BACKEND_PACKAGES = {
    "sb3": (("stable_baselines3", "stable-baselines3"), ("sb3_contrib", "sb3-contrib"),
            ("torch", "torch")),
    "sbx": (("sbx", "sbx-rl"), ("jax", "jax"), ("jaxlib", "jaxlib"), ("flax", "flax"),
            ("optax", "optax"), ("stable_baselines3", "stable-baselines3")),
}


def sbx_available() -> bool:
    """Whether SBX and JAX can be imported (checked without importing them)."""
    return all(importlib.util.find_spec(name) is not None for name in ("sbx", "jax", "flax"))


def check_backend_choice(backend: str) -> str:
    """``auto``, ``sb3`` or ``sbx`` in lower case; :class:`UsageError` otherwise."""
    return one_of(backend, BACKEND_CHOICES, "backend")


def resolve_backend(backend: str, algo: str) -> str:
    """The backend (``sb3`` or ``sbx``) that trains ``algo`` for the choice ``backend``.

    Raises:
        BackendUnavailableError: ``sbx`` without SBX installed; an algorithm whose library is
            missing on the chosen backend (tqc/crossq on sb3 without sb3-contrib).
        UsageError: an unknown backend or algorithm.
    """
    choice, algo = check_backend_choice(backend), check_algo(algo)
    if choice == "sbx" and not sbx_available():
        raise BackendUnavailableError("--backend sbx needs the sbx-rl and jax packages, which "
                                      f"are not installed ({install_hint('sbx')})")
    resolved = ("sbx" if sbx_available() else "sb3") if choice == "auto" else choice
    if resolved == "sb3":
        module_name = ALGO_CLASSES[("sb3", algo)][0]
        if importlib.util.find_spec(module_name) is None:
            hint = " or use --backend sbx" if sbx_available() else \
                " or install rehabbot[jax] for the sbx backend"
            raise BackendUnavailableError(
                f"{ALGO_NAMES[algo]} on the sb3 backend needs the "
                f"{DISTRIBUTIONS[module_name]} package, which is not installed "
                f"({install_hint(module_name)}{hint})")
        algo_class(algo, "sb3")  # an sb3-contrib without CrossQ: a clear error now
    return resolved


def saved_backend(manifest: dict | None) -> str:
    """The backend a run was trained with (runs from before backends existed: sb3)."""
    value = (manifest or {}).get("backend") or "sb3"
    return value if value in BACKENDS else "sb3"


def backend_version(backend: str) -> str | None:
    """The version of the library that implements ``backend`` (None: not installed)."""
    return distribution_version(BACKEND_PACKAGES[backend][0][1])


def backend_versions(backend: str) -> dict[str, str | None]:
    """Versions of the libraries a run on ``backend`` depends on, by import name."""
    return {name: distribution_version(dist) for name, dist in BACKEND_PACKAGES[backend]}
