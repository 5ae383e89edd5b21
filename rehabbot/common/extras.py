"""Which optional extra of ``pip install "rehabbot[...]"`` brings which module, the one
hint every "missing optional dependency" message uses (:func:`install_hint`), and the check a
command makes before it starts (:func:`require_modules`: one error naming every missing
module and the extras that install them).

``pyproject.toml``'s ``[project.optional-dependencies]`` is the truth; a test reads it and
checks this map against it (``tests/test_clinical_workflow.py``).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterable, Mapping

from rehabbot.common.errors import RehabbotError

# import name -> (distribution on PyPI, extra that installs it)
OPTIONAL_MODULES: dict[str, tuple[str, str]] = {
    "stable_baselines3": ("stable-baselines3", "train"),
    "sb3_contrib": ("sb3-contrib", "train"),
    "torch": ("torch", "train"),
    "tensorboard": ("tensorboard", "train"),
    "tqdm": ("tqdm", "train"),
    "rich": ("rich", "train"),
    "yaml": ("pyyaml", "train"),
    "matplotlib": ("matplotlib", "plot"),
    "scipy": ("scipy", "plot"),
    "imageio": ("imageio", "video"),
    "imageio_ffmpeg": ("imageio-ffmpeg", "video"),
    "ray": ("ray", "sweep"),
    "sbx": ("sbx-rl", "jax"),
    "jax": ("jax", "jax"),
    "myo_sim": ("myo-sim", "myo"),
    "warp": ("warp-lang", "gpu"),
    "rsl_rl": ("rsl-rl-lib", "gpu"),
    "onnx": ("onnx", "onnx"),
    "onnxruntime": ("onnxruntime", "onnx"),
    "pylibfranka": ("pylibfranka", "franka"),
    "rtde_control": ("ur_rtde", "ur"),
    "rtde_receive": ("ur_rtde", "ur"),
}


class MissingExtraError(RehabbotError, ImportError):
    """An optional dependency a command needs is not installed (CLI exit 1); the message
    names the modules' distributions and the ``pip install`` that brings them."""


def extra_for(module: str) -> str:
    """The extra that installs ``module`` (its top-level import name: ``yaml``,
    ``matplotlib.pyplot`` counts as ``matplotlib``).

    Raises:
        ValueError: ``module`` is not an optional dependency of RehabBot (naming it).
    """
    top = module.split(".", 1)[0]
    if top not in OPTIONAL_MODULES:
        raise ValueError(f"{module!r} is not an optional dependency of rehabbot (known: "
                         f"{', '.join(sorted(OPTIONAL_MODULES))})")
    return OPTIONAL_MODULES[top][1]


def install_hint(module: str) -> str:
    """``pip install "rehabbot[EXTRA]"`` for the extra that installs ``module``."""
    return f'pip install "rehabbot[{extra_for(module)}]"'


def missing_module_message(what: str, module: str) -> str:
    """``<what> needs <distribution>: pip install "rehabbot[EXTRA]"``."""
    distribution = OPTIONAL_MODULES[module.split(".", 1)[0]][0] if module.split(".", 1)[0] \
        in OPTIONAL_MODULES else module
    return f"{what} needs {distribution}: {install_hint(module)}"


def extras_hint(extras: Iterable[str]) -> str:
    """``pip install "rehabbot[a,b]"`` for the extras ``extras`` (sorted, once each)."""
    return f'pip install "rehabbot[{",".join(sorted(set(extras)))}]"'


def is_installed(module: str) -> bool:
    """Whether ``module`` (a top-level name) can be imported, found without importing it."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or half-removed installation
        return False


def missing_modules(modules: Iterable[str]) -> list[str]:
    """The modules of ``modules`` (top-level optional ones, :data:`OPTIONAL_MODULES`) that are
    not installed, in order, once each."""
    return [module for module in dict.fromkeys(modules) if not is_installed(module)]


def require_modules(what: str, modules: Iterable[str] | Mapping[str, str]) -> None:
    """Check, without importing them, that ``modules`` are installed before ``what`` starts.
    ``modules`` maps each module to the extra that brings it for ``what`` (``torch`` comes
    with ``gpu`` for the batched backend, with ``train`` for Stable-Baselines3); a plain list
    takes each module's own extra (:func:`extra_for`).

    Raises:
        MissingExtraError: ``<what> needs <distributions>, which are not installed: pip
            install "rehabbot[<extras>]"`` (every missing one, in one line).
        ValueError: a module that is not an optional dependency of RehabBot.
    """
    extras = dict(modules) if isinstance(modules, Mapping) else \
        {module: extra_for(module) for module in modules}
    missing = missing_modules(extras)
    if not missing:
        return
    names = [OPTIONAL_MODULES[module.split(".", 1)[0]][0] if module.split(".", 1)[0]
             in OPTIONAL_MODULES else module for module in missing]
    listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
    verb = "is" if len(names) == 1 else "are"
    raise MissingExtraError(f"{what} needs {listed}, which {verb} not installed: "
                            f"{extras_hint(extras[module] for module in missing)}")
