"""Taking a run folder for writing (:func:`lock_run_dir`): the folder is created (a new run),
refused if it is a symbolic link, locked with ``flock`` for as long as the process trains it
(a second writer gets :class:`~rehabbot.common.files.FolderLockedError` with the holder's
pid), and checked again under the lock, so that two processes never mix two runs in one
folder. Emptying it (``--overwrite``) and cleaning up after a failed start never follow a
link (:func:`~rehabbot.common.files.remove_contents`)."""

from __future__ import annotations

import contextlib
from pathlib import Path

from rehabbot.common.files import FolderLock, make_dirs, remove_contents, remove_tree
from rehabbot.rl import runs
from rehabbot.rl.planning import RunPlan, TrainingError, find_resume_point


def lock_run_dir(plan: RunPlan) -> tuple[FolderLock, Path | None]:
    """Create (a new run) and lock the run folder, then check that nothing changed since
    ``plan`` was made; returns the lock and the topmost folder this call created.

    Raises:
        DataError: the run folder is a symbolic link.
        FolderLockedError: (an OutputError) another process writes the run folder.
        TrainingError: another process started or advanced the run since it was planned.
    """
    run_dir = plan.run_dir
    runs.check_run_dir(run_dir, plan.out_dir)
    created_root = make_dirs(run_dir) if plan.resume is None else None
    lock = FolderLock(run_dir, runs.LOCK_NAME).acquire("run folder")
    try:
        if plan.resume is None and not plan.overwrite and runs.has_content(run_dir):
            raise TrainingError(f"{run_dir} already holds a run ({runs.describe(run_dir)}), "
                                "written by another process since this one started; continue "
                                "it with --resume or start over with --overwrite")
        if plan.resume is not None:
            now = find_resume_point(run_dir, runs.read_manifest(run_dir))
            if now is None or now.checkpoint != plan.resume.checkpoint:
                raise TrainingError(f"{run_dir} changed since this process planned to resume "
                                    f"it from {plan.resume.checkpoint.name} (another process "
                                    "trained it); run --resume again")
    except BaseException:
        lock.release()
        raise
    return lock, created_root


def prepare_run_dir(plan: RunPlan) -> None:
    """A new run: empty the folder (``overwrite``; links are removed, never followed) and
    make its subfolders. A resumed run: drop the temporary files of a killed process."""
    run_dir = plan.run_dir
    if plan.resume is None:
        if plan.overwrite:
            remove_contents(run_dir, keep=(runs.LOCK_NAME,))
        for sub in (runs.MONITOR_DIR, runs.CHECKPOINT_DIR):
            (run_dir / sub).mkdir(exist_ok=True)
        return
    for stale in (*run_dir.glob(".*.tmp*"), *(run_dir / runs.CHECKPOINT_DIR).glob(".*.tmp*")):
        with contextlib.suppress(OSError):
            stale.unlink()


def discard_new_run(plan: RunPlan, created_root: Path | None) -> None:
    """Leave nothing of a new run that failed to start (never following a link)."""
    if created_root is not None:
        remove_tree(created_root)
    else:
        remove_contents(plan.run_dir, keep=(runs.LOCK_NAME,))
