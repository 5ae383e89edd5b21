"""The run folder that ``rehabbot train`` writes, and everything that reads it back.

::

    OUT/<env-short>/<algo>/seed<k>/
        manifest.json                      what ran, how far it got, with which versions
        monitor/train_<i>.monitor.csv      SB3 Monitor of training sub-env i
                                           (info keywords: is_success, safety_violation)
        eval/evaluations.npz               SB3 EvalCallback log (deterministic episodes)
        tb/<ALGO>_1/                       TensorBoard event files
        checkpoints/rl_model_<n>_steps.zip (+ rl_model_replay_buffer_<n>_steps.npz, newest
                                           only, for SAC/TD3;
                                           + rl_model_vecnormalize_<n>_steps.json)
        model.zip                          the final model (once the run has finished)
        policy.npz                         instead of model.zip, for a batched run
                                           (--backend rsl_rl): its actor in the zoo format
                                           (see rehabbot.rl.batch_training for its files)
        vecnormalize.json                  the final VecNormalize statistics (if normalized;
                                           JSON, :mod:`rehabbot.rl.vecnormalize_io`)
        evaluation/<policy>/               what ``rehabbot evaluate`` wrote for the run's model
        .lock                              held (flock) by the process that writes the run

A run folder must be a real folder, not a symbolic link (:func:`check_run_dir`), and nothing
in it is unpickled when it is read back (see :mod:`rehabbot.rl.safe_load`).

This module is the one place that knows these names: training writes them, evaluation,
plotting and the policy loader read them.
"""

from __future__ import annotations

import csv
import io
import json
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError
from rehabbot.common.files import atomic_write
from rehabbot.envs.registration import env_short_name

MANIFEST_NAME = "manifest.json"
MODEL_NAME = "model.zip"
# A batched run (``--backend rsl_rl``, :mod:`rehabbot.rl.batch_training`) exports its actor here
# (the zoo's format) instead of a model.zip.
BATCH_POLICY_NAME = "policy.npz"
VECNORMALIZE_NAME = "vecnormalize.json"
LEGACY_VECNORMALIZE_NAME = "vecnormalize.pkl"  # pickled: refused, see vecnormalize_io
LOCK_NAME = ".lock"
CHECKPOINT_DIR = "checkpoints"
MONITOR_DIR = "monitor"
EVAL_DIR = "eval"
EVALUATIONS_PATH = Path(EVAL_DIR) / "evaluations.npz"
EVALUATION_DIR = "evaluation"
TB_DIR = "tb"
CHECKPOINT_PREFIX = "rl_model"
CHECKPOINT_RE = re.compile(rf"^{CHECKPOINT_PREFIX}_(\d+)_steps\.zip$")
MANIFEST_FORMAT = 1
MANIFEST_REQUIRED = ("env_id", "algo", "seed")


def run_directory(out_dir: str | Path, env_id: str, algo: str, seed: int) -> Path:
    """``OUT/<env-short>/<algo>/seed<k>``."""
    return Path(out_dir) / env_short_name(env_id) / algo.lower() / f"seed{int(seed)}"


def read_manifest(run_dir: Path) -> dict[str, Any] | None:
    """The run's ``manifest.json`` (None if there is none).

    Raises:
        DataError: the file is unreadable, not JSON, not an object, or lacks env_id, algo or
            seed (the message names the file).
    """
    path = Path(run_dir) / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataError(f"{path} is not a readable manifest: {err}") from err
    if not isinstance(manifest, dict):
        raise DataError(f"{path} is not a readable manifest: not a JSON object")
    missing = [key for key in MANIFEST_REQUIRED if key not in manifest]
    if missing:
        raise DataError(f"{path} is not a readable manifest: it lacks {', '.join(missing)}")
    return manifest


def final_model(run_dir: Path) -> Path | None:
    """The final model of a finished run: ``model.zip``, or a batched run's ``policy.npz``
    (None while neither is there)."""
    for name in (MODEL_NAME, BATCH_POLICY_NAME):
        if (Path(run_dir) / name).is_file():
            return Path(run_dir) / name
    return None


def find_run_dir(path: Path) -> Path | None:
    """The run directory a model file belongs to (its own folder, or its parent for
    ``checkpoints/``), recognised by its manifest; None for a loose model file."""
    path = Path(path)
    for folder in (path.parent, path.parent.parent):
        if (folder / MANIFEST_NAME).is_file():
            return folder
    return None


def checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """The run's checkpoints as (steps, path), newest first."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    if not folder.is_dir():
        return []
    found = []
    for path in folder.iterdir():
        match = CHECKPOINT_RE.match(path.name)
        if match and path.is_file():
            found.append((int(match.group(1)), path))
    return sorted(found, reverse=True)


def companions(checkpoint_dir: Path, steps: int) -> tuple[Path, Path]:
    """The replay-buffer and VecNormalize files saved with the checkpoint of ``steps``."""
    return (checkpoint_dir / f"{CHECKPOINT_PREFIX}_replay_buffer_{steps}_steps.npz",
            checkpoint_dir / f"{CHECKPOINT_PREFIX}_vecnormalize_{steps}_steps.json")


def stored(path: Path) -> Path | None:
    """``path`` if it exists, else its legacy pickled twin (``.pkl``: refused, with a message
    that says how to convert it, when it is read), else None."""
    if path.is_file():
        return path
    legacy = path.with_suffix(".pkl")
    return legacy if legacy.is_file() else None


def has_content(run_dir: Path) -> bool:
    """Whether ``run_dir`` holds anything besides its lock file."""
    run_dir = Path(run_dir)
    return run_dir.is_dir() and any(child.name != LOCK_NAME for child in run_dir.iterdir())


def check_run_dir(run_dir: Path, out_dir: Path) -> None:
    """Refuse a run folder that is a symbolic link or lies below one under ``out_dir``
    (``OUT/<env>/<algo>/seed<k>``): deleting or writing it would reach outside the output tree.

    Raises:
        DataError: naming the link.
    """
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    probe = run_dir
    while probe != out_dir and probe != probe.parent:
        if probe.is_symlink():
            raise DataError(f"refusing run folder {run_dir}: {probe} is a symbolic link (to "
                            f"{probe.readlink()}); a run folder must be a real folder inside "
                            f"{out_dir}")
        probe = probe.parent


def describe(run_dir: Path) -> str:
    """``status S, N of M steps`` (or why not) for messages about an existing run."""
    try:
        manifest = read_manifest(run_dir)
    except DataError:
        manifest = None
    if manifest:
        return (f"status {manifest.get('status')}, {manifest.get('timesteps_done')} of "
                f"{manifest.get('total_timesteps')} steps")
    return "files but no manifest"


def format_duration(seconds: float) -> str:
    """``42.0 s`` or ``1:02:03``."""
    seconds = max(0.0, float(seconds))
    if seconds < 60:
        return f"{seconds:.1f} s"
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"


def run_summary(run_dir: str | Path) -> str:
    """``DIR: N steps, wall-clock W, last eval at S steps: success X%, mean return R``."""
    path = Path(run_dir)
    manifest = read_manifest(path) or {}
    parts = [f"{path}: {manifest.get('timesteps_done', '?')} steps",
             f"{format_duration(float(manifest.get('wall_clock_s', 0.0)))} wall-clock"]
    evaluations = path / EVALUATIONS_PATH
    text = "no evaluation"
    if evaluations.is_file():
        try:
            with np.load(evaluations, allow_pickle=False) as data:
                if len(data["timesteps"]):
                    ret = float(np.mean(data["results"][-1]))
                    text = f"last eval at {int(data['timesteps'][-1])} steps: "
                    if "successes" in data.files and len(data["successes"]):
                        text += f"success {100 * float(np.mean(data['successes'][-1])):.0f}%, "
                    text += f"mean return {ret:.1f}"
        except (OSError, KeyError, ValueError):
            text = "evaluation log unreadable"
    parts.append(text)
    return ", ".join(parts)




def truncate_monitor(path: Path, max_steps: int) -> float:
    """Drop rows past ``max_steps`` env steps (written after the checkpoint we resume from);
    returns the ``t`` of the last row kept (0 if none)."""
    if not path.is_file():
        return 0.0
    with path.open(newline="", encoding="utf-8") as stream:
        header = stream.readline()
        reader = csv.reader(stream)
        try:
            columns = next(reader)
        except StopIteration:
            return 0.0
        rows = list(reader)
    try:
        l_col, t_col = columns.index("l"), columns.index("t")
    except ValueError:
        return 0.0
    kept, steps, last_t = [], 0, 0.0
    for row in rows:
        try:
            length, t = int(float(row[l_col])), float(row[t_col])
        except (IndexError, ValueError):
            break
        if steps + length > max_steps:
            break
        steps += length
        last_t = t
        kept.append(row)
    if len(kept) != len(rows):
        out = io.StringIO(newline="")
        out.write(header)
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(kept)
        atomic_write(path, lambda stream: stream.write(out.getvalue().encode("utf-8")))
    return last_t


def load_evaluations(path: Path, max_steps: int) -> dict[str, list] | None:
    """SB3's ``evaluations.npz`` up to ``max_steps`` as lists (None: missing or unreadable,
    with a warning), to carry on after a resume."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            timesteps = [int(t) for t in data["timesteps"]]
            keep = [i for i, t in enumerate(timesteps) if t <= max_steps]
            result = {
                "timesteps": [timesteps[i] for i in keep],
                "results": [list(map(float, data["results"][i])) for i in keep],
                "ep_lengths": [list(map(int, data["ep_lengths"][i])) for i in keep],
                "successes": [list(map(bool, data["successes"][i])) for i in keep]
                if "successes" in data.files and len(data["successes"]) == len(timesteps)
                else [],
            }
    except (OSError, KeyError, ValueError, EOFError) as err:
        warnings.warn(f"ignoring unreadable {path}: {err}", stacklevel=2)
        return None
    return result
