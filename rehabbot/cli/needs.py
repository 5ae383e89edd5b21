"""What a command needs beyond the core install, checked before it does anything
(:func:`rehabbot.common.extras.require_modules`: one line naming ``pip install
"rehabbot[EXTRA]"``, exit 1), so that a missing extra never shows up after minutes of work.

========================  ==========================================================
``list``, ``scenes``      nothing (the core install)
``train``                 ``[train]`` (SB3, PyTorch, PyYAML, TensorBoard); the default
                          backend, ``auto``, trains on SBX (JAX) when ``[jax]`` is
                          installed too, else on SB3; ``--backend rsl_rl``: ``[gpu]``
``evaluate``/``render``   for a model zip, its backend's library: ``[train]`` (SB3) or
                          ``[jax]`` (SBX); ``render`` also ``[video]`` (an .mp4 needs
                          imageio-ffmpeg, a .gif imageio only)
``plot``                  ``[plot]`` (and what evaluating a model needs, if it does)
``snapshot``              ``[video]`` (imageio writes the PNG)
``sweep``                 ``[train]`` and ``[sweep]`` (Ray Tune; not for ``--dry-run``)
``demo``                  ``[train]``, ``[plot]`` and ``[video]`` (not with ``--no-video``)
``export``                ``[onnx]`` (and, for a model zip, its backend's library)
``deploy``                what the policy needs (``[onnx]``'s onnxruntime for an ONNX file);
                          ``--backend franka``: ``[franka]``; ``--backend ur``: ``[ur]``
``calibrate``             nothing (the core install)
========================  ==========================================================
"""

from __future__ import annotations

from pathlib import Path

# Each group: the modules a command imports, mapped to the extra that brings them.
# What `rehabbot train` imports on either CPU backend (SBX builds on Stable-Baselines3, its
# runs log to TensorBoard through it, and settings files are YAML).
TRAIN_MODULES = {"stable_baselines3": "train", "torch": "train", "yaml": "train",
                 "tensorboard": "train"}
SBX_MODULES = {"sbx": "jax", "jax": "jax"}
CONTRIB_MODULES = {"sb3_contrib": "train"}  # TQC and CrossQ on the sb3 backend
CONTRIB_ALGOS = ("tqc", "crossq")
# The batched backend (rehabbot.rl.batch_training.BATCH_MODULES).
BATCH_MODULES = {"jax": "gpu", "warp": "gpu", "torch": "gpu", "rsl_rl": "gpu"}
PLOT_MODULES = {"matplotlib": "plot"}
GIF_MODULES = {"imageio": "video"}
MP4_MODULES = {"imageio": "video", "imageio_ffmpeg": "video"}
SWEEP_MODULES = {"ray": "sweep"}
# The library that loads a model zip of each backend.
BACKEND_MODULES = {"sb3": {"stable_baselines3": "train", "torch": "train"},
                   "sbx": SBX_MODULES}
NOTHING: dict[str, str] = {}


def require(what: str, *groups: dict[str, str]) -> None:
    """Refuse to start ``what`` unless every module of ``groups`` is installed
    (:class:`~rehabbot.common.extras.MissingExtraError`, naming all that are missing and the
    extras that bring them)."""
    from rehabbot.common.extras import require_modules

    needed: dict[str, str] = {}
    for group in groups:
        for module, extra in group.items():
            needed.setdefault(module, extra)
    require_modules(what, needed)


def train_modules(algo: str, backend: str) -> dict[str, str]:
    """What ``rehabbot train --algo ALGO --backend BACKEND`` imports (``auto``: SBX's when it
    is installed, else SB3's)."""
    if backend == "rsl_rl":
        return BATCH_MODULES
    from rehabbot.rl.backends import sbx_available

    on_sbx = backend == "sbx" or (backend == "auto" and sbx_available())
    if on_sbx:
        return {**TRAIN_MODULES, **SBX_MODULES}
    return {**TRAIN_MODULES, **(CONTRIB_MODULES if algo.lower() in CONTRIB_ALGOS else {})}


def video_modules(path: Path | str) -> dict[str, str]:
    """What writing the video ``path`` needs: imageio, and imageio-ffmpeg for an .mp4."""
    return GIF_MODULES if str(path).lower().endswith(".gif") else MP4_MODULES


def policy_modules(spec: str) -> dict[str, str]:
    """What loading the policy ``spec`` needs: nothing for ``expert``, ``aan``, ``random``, a
    zoo agent, a batched run's ``policy.npz`` or a missing file (whose error comes from the
    loader, naming it); the backend's library for a model zip (its run's manifest says which,
    else the zip's own metadata)."""
    from rehabbot.common.errors import RehabbotError
    from rehabbot.rl import runs
    from rehabbot.rl.algorithms import detect_model
    from rehabbot.rl.backends import saved_backend
    from rehabbot.rl.policies import POLICY_KEYWORDS, model_file
    from rehabbot.rl.zoo import is_zoo_spec

    if spec in POLICY_KEYWORDS or is_zoo_spec(spec):
        return NOTHING
    try:
        path = model_file(spec)
        if path.suffix == ".npz":
            return NOTHING
        algo, backend = detect_model(path)
        run_dir = runs.find_run_dir(path)
        manifest = runs.read_manifest(run_dir) if run_dir is not None else None
    except (RehabbotError, ValueError, OSError):
        return NOTHING  # the loader reports a missing or damaged file, naming it
    if manifest and manifest.get("backend"):
        backend = saved_backend(manifest)
    contrib = CONTRIB_MODULES if backend == "sb3" and algo in CONTRIB_ALGOS else NOTHING
    return {**BACKEND_MODULES.get(backend, NOTHING), **contrib}
