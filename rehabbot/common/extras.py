"""Which optional extra of ``pip install "rehabbot[...]"`` brings which module, and the one
hint every "missing optional dependency" message uses (:func:`install_hint`).

``pyproject.toml``'s ``[project.optional-dependencies]`` is the truth; a test reads it and
checks this map against it (``tests/test_extras.py``).
"""

from __future__ import annotations

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
}


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
