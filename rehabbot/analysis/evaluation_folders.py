"""Where ``rehabbot evaluate`` writes, and what it never writes or removes through.

An evaluation folder ``OUT`` holds one *label folder* per policy (``OUT/<label>/``:
``evaluation.json``, ``trace.npz``, with a population ``patients.md``) and, for several
policies, ``OUT/comparison.md``.

===================================  ==========================================================
function                             what
===================================  ==========================================================
:func:`default_out_dir`              the folder an evaluation without ``--out`` writes: one of
                                     its own for each set of policies compared, so that two
                                     evaluations never meet in one default folder
:func:`earlier_evaluation`           the files an earlier evaluation left in ``OUT``
:func:`remove_earlier_evaluation`    removes them (``--overwrite``), and the label folders
                                     they leave empty; never through a link
:func:`check_label_folders`          refuses a label folder that is a symbolic link: removing
                                     or writing through it would reach outside ``OUT``
:func:`lock_run_folders`             takes the lock of every training run folder the
                                     evaluation writes into: never into a live run's folder
===================================  ==========================================================
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

from rehabbot.analysis.policy_specs import PolicySpec, is_named_spec
from rehabbot.analysis.traces import TRACE_NAME
from rehabbot.common.errors import OutputError
from rehabbot.common.files import FolderLock
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import runs
from rehabbot.rl.policies import POLICY_KEYWORDS, model_file
from rehabbot.rl.zoo import is_zoo_spec

REPORT_NAME = "evaluation.json"
COMPARISON_NAME = "comparison.md"
PATIENTS_NAME = "patients.md"
LABEL_FOLDER_FILES = (REPORT_NAME, TRACE_NAME, PATIENTS_NAME)  # what a label folder holds
DEFAULT_ROOT = Path("runs") / "evaluation"
LABEL_SEPARATOR = "+"  # joins the labels in a default folder's name (never part of a label)
MAX_FOLDER_NAME = 120


def comparison_name(labels: Sequence[str]) -> str:
    """The name of the default folder of an evaluation of ``labels`` (in the order given):
    ``sac-seed0+expert+random``; a name longer than :data:`MAX_FOLDER_NAME` keeps its first
    two labels, the count of the others and a hash of them all."""
    name = LABEL_SEPARATOR.join(labels)
    if len(name) <= MAX_FOLDER_NAME:
        return name
    digest = hashlib.sha256(name.encode("utf-8")).hexdigest()[:8]
    head = LABEL_SEPARATOR.join(label[:40] for label in labels[:2])
    return f"{head}+{len(labels) - 2}-more-{digest}"


def _run_dirs(specs: Sequence[PolicySpec]) -> list[Path | None]:
    """The training run folder of each model among ``specs`` (None: a loose model file)."""
    return [runs.find_run_dir(model_file(spec)) for spec in specs
            if is_named_spec(spec) and str(spec) not in POLICY_KEYWORDS
            and not is_zoo_spec(spec)]


def default_out_dir(specs: Sequence[PolicySpec], env_id: str, labels: Sequence[str]) -> Path:
    """The folder of an evaluation without ``--out``:

    - one model of a ``rehabbot train`` run alone: ``<run>/evaluation`` (where ``rehabbot
      plot`` evaluates a run too);
    - models of training runs of ``env_id``, all under one ``<OUT>/<env>/`` (the layout
      ``rehabbot train`` writes), with or without other policies:
      ``<OUT>/<env>/evaluation/<labels>`` (so ``rehabbot plot <OUT>/<env>`` draws it);
    - else ``runs/evaluation/<env>/<labels>``,

    ``<labels>`` being :func:`comparison_name`: each set of policies compared has a folder of
    its own, and only the same comparison meets an earlier one there.
    """
    run_dirs = _run_dirs(specs)
    if len(specs) == 1 and len(run_dirs) == 1 and run_dirs[0] is not None:
        return run_dirs[0] / runs.EVALUATION_DIR
    short = env_short_name(env_id)
    env_dirs = {run_dir.parent.parent for run_dir in run_dirs if run_dir is not None}
    if (run_dirs and None not in run_dirs and len(env_dirs) == 1
            and next(iter(env_dirs)).name == short):
        root = env_dirs.pop() / runs.EVALUATION_DIR
    else:
        root = DEFAULT_ROOT / short
    return root / comparison_name(labels)


def _label_folders(out_dir: Path) -> Iterator[Path]:
    """The entries of ``out_dir`` that are (or point to) folders, sorted by name."""
    if not out_dir.is_dir():
        return
    for child in sorted(out_dir.iterdir()):
        if child.is_dir():  # also a link to a folder
            yield child


def _holds_evaluation(folder: Path) -> bool:
    return any((folder / name).is_file() or (folder / name).is_symlink()
               for name in LABEL_FOLDER_FILES)


def check_label_folders(out_dir: Path, labels: Sequence[str] = ()) -> None:
    """Refuse an output folder whose label folder is a symbolic link: one of ``labels`` (it
    would be written through), or one that holds an earlier evaluation's files (they would be
    removed through it).

    Raises:
        OutputError: naming the link and where it points.
    """
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return
    for child in sorted(out_dir.iterdir()):
        if not child.is_symlink():
            continue
        if child.name in labels or (child.is_dir() and _holds_evaluation(child)):
            raise OutputError(
                f"refusing {child}: this label folder of {out_dir} is a symbolic link (to "
                f"{os.readlink(child)}); an evaluation writes and removes files only inside "
                "its own folder, never through a link: remove the link or choose another "
                "--out")


def earlier_evaluation(out_dir: Path) -> list[Path]:
    """The files of an earlier evaluation in ``out_dir``: ``comparison.md`` and every
    ``<label>/evaluation.json``, ``<label>/trace.npz`` and ``<label>/patients.md`` of a label
    folder that is a real folder (a linked one is refused by :func:`check_label_folders`)."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return []
    comparison = out_dir / COMPARISON_NAME
    found = [comparison] if comparison.is_file() or comparison.is_symlink() else []
    folders = [folder for folder in _label_folders(out_dir) if not folder.is_symlink()]
    for name in LABEL_FOLDER_FILES:
        found += [folder / name for folder in folders
                  if (folder / name).is_file() or (folder / name).is_symlink()]
    return found


def remove_earlier_evaluation(out_dir: Path, keep: Sequence[Path] = ()) -> list[Path]:
    """Remove :func:`earlier_evaluation`'s files but those in ``keep`` (the files a new
    evaluation has just written over them), and then every label folder left empty; never
    following a link (a linked label folder is refused first). Returns the removed files.

    Raises:
        OutputError: a label folder of ``out_dir`` is a symbolic link (nothing is removed).
    """
    out_dir = Path(out_dir)
    check_label_folders(out_dir)
    kept = {os.path.abspath(path) for path in keep}
    removed = [path for path in earlier_evaluation(out_dir)
               if os.path.abspath(path) not in kept]
    for path in removed:
        path.unlink()
    for folder in dict.fromkeys(path.parent for path in removed):
        if folder != out_dir and not folder.is_symlink() and not any(folder.iterdir()):
            folder.rmdir()
    return removed


def _run_folders(out_dir: Path, labels: Sequence[str]) -> list[Path]:
    """The training run folders (holding ``manifest.json``; a ``.lock`` alone could be
    anyone's file) an evaluation into ``out_dir``
    writes into: ``out_dir`` itself, a folder above it, or one of its label folders."""
    out = Path(os.path.abspath(out_dir))
    candidates = [out, *out.parents, *(out / label for label in labels)]
    return [folder for folder in candidates if (folder / runs.MANIFEST_NAME).is_file()]


@contextlib.contextmanager
def lock_run_folders(out_dir: Path, labels: Sequence[str] = ()) -> Iterator[list[Path]]:
    """Hold the lock (``.lock``, :class:`~rehabbot.common.files.FolderLock`) of every training
    run folder that an evaluation into ``out_dir`` writes into, for as long as the ``with``
    block runs: a run that is being trained holds its lock, so writing into its folder is
    refused, naming it; and a training started meanwhile waits for the evaluation to end.

    Raises:
        FolderLockedError: (an OutputError) a live process writes one of those run folders.
    """
    with contextlib.ExitStack() as stack:
        folders = _run_folders(out_dir, labels)
        for folder in folders:
            try:
                lock = FolderLock(folder, runs.LOCK_NAME).acquire("run folder")
            except OutputError:  # held by a live process, or a link: says so
                raise
            except OSError as err:
                raise OutputError(f"cannot lock run folder {folder}: "
                                  f"{err.strerror or err}") from err
            stack.callback(lock.release)
        yield folders
