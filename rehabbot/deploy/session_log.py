"""A deployment session on disk: written as it runs, so that nothing finished is lost.

A session folder holds ``session.json`` (what ran: the policy, the env, the backend, the
filter's settings, the seeds, the status) and one ``episode-NNNN.npz`` per episode. Each
episode file is written atomically (:mod:`rehabbot.common.files`) when its episode ends, and
``session.json`` is rewritten atomically after it, so an interrupted session keeps every
episode that ended and the one that was running (its ``end`` says why it ended), and a crash
at any instant leaves only complete files. ``status`` is ``running`` while the session runs,
then ``completed``, ``stopped`` (the filter or a fault stopped the robot), ``interrupted``
(SIGINT/SIGTERM) or ``failed`` (an error; ``reason`` names it).

An episode file (``allow_pickle=False``; T decisions; rows of the ``(T + 1, ...)`` arrays are
the state before each decision and, last, the state after the last one):

=========================  =================================================================
key                        what
=========================  =================================================================
``episode``, ``seed``      the episode's number in the session and its reset seed (-1: none)
``end``                    ``terminated``, ``truncated``, ``filter_stop``, ``robot_fault``,
                           ``interrupted`` or ``failed``
``dt_s``                   the decision period [s]
``joint_names``            (n,) the robot's joints; ``patient_joint_names`` (m,) the
                           exercised patient joints
``time_s``                 (T + 1,) the simulator's (twin's) time [s]
``q_rad``, ``dq_rad_s``    (T + 1, n) the simulated robot's joints
``cuff_force_n``           (T + 1,) the force in the cuff [N]
``patient_q_rad``,         (T + 1, m) the exercised patient joints
``patient_dq_rad_s``
``target_index``           (T + 1,) the active target
``observation``            (T + 1, d) what the policy saw (the last row: after the last step)
``policy_action``          (T, a) the policy's actions
``q_policy_rad``           (T, n) the joint command of each action, before the filter
``q_command_rad``          (T, n) the command after the filter (what the robot was sent)
``filter_action``          (T,) ``pass``, ``clip``, ``hold``, ``back_off`` or ``stop``
``filter_reasons``         (T,) the filter's reasons, ``"; "``-separated (empty: none)
``stepped``                (T,) whether the command was sent (False only for ``stop``)
``reward``                 (T,) the env's reward (NaN where nothing was sent)
``is_success``             (T,) the env's ``is_success`` after each decision
``safety_violation``       (T,) the env's safety rule that stopped its episode at that
                           decision (empty: none)
``wall_s``                 (T,) wall-clock seconds from reading the state to the command's
                           return
``target_patient_deg``     (N, m) the exercised joints at every target (the prescribed path)
``target_robot_rad``       (N, n) the robot's joints at every target
``rom_low_rad``,           (m,) the exercised joints' range of motion
``rom_high_rad``
``cuff_force_limit_n``     the cuff's force limit [N]
=========================  =================================================================

In shadow mode (a real robot driven beside the simulator, :mod:`rehabbot.deploy.session`)
the file also holds the robot's own measurements and the two filters' verdicts:
``robot_time_s`` (T + 1,), ``robot_q_rad`` and ``robot_dq_rad_s`` (T + 1, n),
``robot_cuff_force_n`` (T + 1,) (NaN where the robot has no estimate), ``tracking_error_rad``
(T + 1, n) ``robot_q_rad - q_rad``, ``twin_filter_action`` and ``robot_filter_action`` (T,),
and the approach to the episode's start pose before it: ``approach_q_command_rad`` (K, n),
the robot filter's action on each and its reasons, ``approach_filter_action`` and
``approach_filter_reasons`` (K,), and
``approach_robot_q_rad`` (K + 1, n) (K = 0 when the robot was already there).
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import threading
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import DataError, UsageError
from rehabbot.common.files import (
    atomic_write,
    atomic_write_json,
    check_parent_exists,
    check_writable_dir,
    make_dirs,
)
from rehabbot.common.provenance import git_commit, now_iso, package_versions

SESSION_NAME = "session.json"
SESSION_FORMAT = "rehabbot-deploy-session/1"
EPISODE_GLOB = "episode-*.npz"
FILTER_ACTIONS = ("pass", "clip", "hold", "back_off", "stop")
EPISODE_ENDS = ("terminated", "truncated", "filter_stop", "robot_fault", "interrupted", "failed")
STATUSES = ("running", "completed", "stopped", "interrupted", "failed")
REASON_SEPARATOR = "; "
REQUIRED_KEYS = ("episode", "seed", "end", "dt_s", "joint_names", "time_s", "q_rad",
                 "cuff_force_n", "patient_q_rad", "target_index", "q_policy_rad",
                 "q_command_rad", "filter_action", "filter_reasons", "stepped",
                 "cuff_force_limit_n")
SHADOW_KEYS = ("robot_time_s", "robot_q_rad", "robot_dq_rad_s", "robot_cuff_force_n",
               "tracking_error_rad", "twin_filter_action", "robot_filter_action",
               "approach_q_command_rad", "approach_filter_action", "approach_filter_reasons",
               "approach_robot_q_rad")
TEXT_ROWS = ("filter_action", "filter_reasons", "safety_violation", "twin_filter_action",
             "robot_filter_action")
_EPISODE_NAME = re.compile(r"episode-(\d{4,})\.npz")


def episode_name(index: int) -> str:
    """``episode-0003.npz``: the file of episode ``index`` (0-based)."""
    return f"episode-{index:04d}.npz"


# ------------------------------------------------------------------------------- recording
def episode_constants(twin: Any) -> dict[str, Any]:
    """What an episode file holds once (module docstring): read from the simulator backend
    ``twin`` (:class:`~rehabbot.deploy.simulator.SimulatorBackend`) after its reset."""
    sequence = twin.env.target_sequence
    low, high = twin.rom_bounds_rad()
    return {"dt_s": twin.control_dt_s, "joint_names": list(twin.joint_names),
            "patient_joint_names": list(twin.env.scene.exercised_joints),
            "target_patient_deg": np.array(sequence.patient_deg, dtype=float),
            "target_robot_rad": np.array(sequence.robot_rad, dtype=float),
            "rom_low_rad": low, "rom_high_rad": high,
            "cuff_force_limit_n": twin.cuff_force_limit_n()}


class EpisodeRecorder:
    """The rows of one episode as the loop produces them (module docstring's keys).

    :meth:`state` appends a state row (before each decision, and once after the last),
    :meth:`decision` a decision row; :meth:`arrays` returns the episode file's arrays.
    """

    def __init__(self, episode: int, seed: int | None, constants: Mapping[str, Any],
                 shadow: bool) -> None:
        self.episode = int(episode)
        self.seed = -1 if seed is None else int(seed)
        self.constants = dict(constants)
        self.shadow = shadow
        self.rows: dict[str, list[Any]] = {}
        self.approach_commands: list[np.ndarray] = []
        self.approach_measured: list[np.ndarray] = []
        self.approach_actions: list[str] = []
        self.approach_reasons: list[str] = []
        self.end: str | None = None

    def _add(self, **values: Any) -> None:
        for key, value in values.items():
            self.rows.setdefault(key, []).append(value)

    @property
    def decisions(self) -> int:
        """Decisions recorded so far."""
        return len(self.rows.get("q_command_rad", ()))

    def state(self, twin: Any, observation: np.ndarray, target_index: int,
              robot: Any | None = None) -> None:
        """A state row: the twin's :class:`~rehabbot.deploy.backend.RobotState`, the policy's
        observation, the active target and, in shadow mode, the robot's state."""
        self._add(time_s=twin.time_s, q_rad=twin.q_rad, dq_rad_s=twin.dq_rad_s,
                  cuff_force_n=twin.cuff_force_n, patient_q_rad=twin.patient_q_rad,
                  patient_dq_rad_s=twin.patient_dq_rad_s, target_index=int(target_index),
                  observation=np.asarray(observation))
        if self.shadow:
            if robot is None:
                raise UsageError("a shadow-mode state row needs the robot's state")
            self._add(robot_time_s=robot.time_s, robot_q_rad=robot.q_rad,
                      robot_dq_rad_s=robot.dq_rad_s, robot_cuff_force_n=robot.cuff_force_n,
                      tracking_error_rad=np.asarray(robot.q_rad) - np.asarray(twin.q_rad))

    def decision(self, action: np.ndarray, q_policy_rad: np.ndarray, q_command_rad: np.ndarray,
                 filter_action: str, reasons: Sequence[str], stepped: bool, reward: float,
                 is_success: bool, wall_s: float, safety_violation: str | None = None,
                 twin_action: str | None = None, robot_action: str | None = None) -> None:
        """A decision row (see the module docstring); ``twin_action`` and ``robot_action`` are
        the two filters' verdicts in shadow mode."""
        if filter_action not in FILTER_ACTIONS:
            raise UsageError(f"filter action {filter_action!r} is not one of "
                             f"{list(FILTER_ACTIONS)}")
        self._add(policy_action=np.asarray(action), q_policy_rad=q_policy_rad,
                  q_command_rad=q_command_rad, filter_action=filter_action,
                  filter_reasons=REASON_SEPARATOR.join(reasons), stepped=bool(stepped),
                  reward=float(reward), is_success=bool(is_success), wall_s=float(wall_s),
                  safety_violation=safety_violation or "")
        if self.shadow:
            self._add(twin_filter_action=twin_action or "pass",
                      robot_filter_action=robot_action or "pass")

    def approach(self, q_command_rad: np.ndarray | None, robot_q_rad: np.ndarray,
                 filter_action: str = "pass", reasons: Sequence[str] = ()) -> None:
        """One period of the approach to the start pose (shadow mode): the command sent (None
        for the first measurement) and the robot filter's action on it and its reasons, then
        the robot's joints measured."""
        if q_command_rad is not None:
            self.approach_commands.append(np.array(q_command_rad, dtype=float))
            self.approach_actions.append(filter_action)
            self.approach_reasons.append(REASON_SEPARATOR.join(reasons))
        self.approach_measured.append(np.array(robot_q_rad, dtype=float))

    def arrays(self) -> dict[str, np.ndarray]:
        """The episode file's arrays (``end`` must have been set)."""
        if self.end not in EPISODE_ENDS:
            raise UsageError(f"episode end {self.end!r} is not one of {list(EPISODE_ENDS)}")
        n = len(self.constants["joint_names"])
        out: dict[str, np.ndarray] = {
            "episode": np.array(self.episode), "seed": np.array(self.seed),
            "end": np.array(self.end)}
        for key, value in self.constants.items():
            out[key] = np.asarray(value)
        m = len(self.constants.get("patient_joint_names", ()))
        widths = {"policy_action": 0, "q_policy_rad": n, "q_command_rad": n, "q_rad": n,
                  "dq_rad_s": n, "observation": 0, "patient_q_rad": m, "patient_dq_rad_s": m}
        if self.shadow:
            widths |= dict.fromkeys(("robot_q_rad", "robot_dq_rad_s", "tracking_error_rad"), n)
        for key, rows in self.rows.items():
            if key in TEXT_ROWS:
                out[key] = np.array(rows, dtype=str)
            else:
                out[key] = np.array(rows)
        for key, width in widths.items():  # an episode that ended at once: shaped empties
            if key not in out:
                out[key] = np.zeros((0, width))
        for key in ("filter_action", "filter_reasons", "safety_violation"):
            out.setdefault(key, np.zeros(0, dtype=str))
        for key in ("stepped", "is_success"):
            out.setdefault(key, np.zeros(0, dtype=bool))
        for key in ("reward", "wall_s", "time_s", "cuff_force_n", "robot_time_s",
                    "robot_cuff_force_n")[:6 if self.shadow else 4]:
            out.setdefault(key, np.zeros(0))
        out.setdefault("target_index", np.zeros(0, dtype=int))
        if self.shadow:
            out["approach_q_command_rad"] = np.array(self.approach_commands).reshape(-1, n)
            out["approach_robot_q_rad"] = np.array(self.approach_measured).reshape(-1, n)
            out["approach_filter_action"] = np.array(self.approach_actions, dtype=str)
            out["approach_filter_reasons"] = np.array(self.approach_reasons, dtype=str)
            for key in ("twin_filter_action", "robot_filter_action"):
                out.setdefault(key, np.zeros(0, dtype=str))
        return out

    def summary(self) -> dict[str, Any]:
        """The episode's line in ``session.json``."""
        actions = self.rows.get("filter_action", [])
        counts = {action: actions.count(action) for action in FILTER_ACTIONS
                  if actions.count(action)}
        success = self.rows.get("is_success", [])
        rewards = self.rows.get("reward", [])
        line: dict[str, Any] = {
            "episode": self.episode, "file": episode_name(self.episode), "seed": self.seed,
            "end": self.end, "decisions": self.decisions,
            "return": float(np.nansum(rewards)) if rewards else 0.0,
            "success": bool(success[-1]) if success else False,
            "filter_actions": counts}
        if self.shadow and self.rows.get("tracking_error_rad"):
            error = np.abs(np.array(self.rows["tracking_error_rad"]))
            line["max_tracking_error_rad"] = float(error.max()) if error.size else 0.0
            line["approach_periods"] = len(self.approach_commands)
        return line


# ------------------------------------------------------------------------------- writing
def _plain(config: Any) -> dict[str, Any] | None:
    """A frozen settings dataclass as JSON-ready values (tuples as lists); None stays."""
    if config is None:
        return None
    return {key: list(value) if isinstance(value, tuple) else value
            for key, value in dataclasses.asdict(config).items()}


def session_header(backend: str, policy: Any, env_id: str, env_kwargs: Mapping[str, Any],
                   twin: Any, robot: Mapping[str, Any] | None, twin_filter: Any,
                   robot_filter: Any, episodes: int, seed: int | None,
                   settings: Any) -> dict[str, Any]:
    """What ``session.json`` records before the session starts: the backend, the policy (a
    :class:`~rehabbot.rl.policies.LoadedPolicy`), the env, the twin (the simulator backend)
    and the robot, both filters' settings, the episodes planned, the seed and the session's
    settings (dataclasses)."""
    env = twin.env
    return {"backend": backend, "shadow": robot is not None,
            "policy": {**policy.describe(), "spec": policy.spec},
            "env_id": env_id, "env_kwargs": dict(env_kwargs),
            "twin": {"joint_names": list(twin.joint_names), "control_dt_s": twin.control_dt_s,
                     "robot": env.robot.name,
                     "patient_joint_names": list(env.scene.exercised_joints)},
            "robot": dict(robot) if robot is not None else None,
            "filter": _plain(twin_filter), "robot_filter": _plain(robot_filter),
            "episodes_planned": episodes, "seed": seed, "settings": _plain(settings)}


def _save_npz(stream: io.BufferedWriter, arrays: Mapping[str, np.ndarray]) -> None:
    np.savez_compressed(stream, **arrays)


def check_session_folder(out_dir: Path | str) -> Path:
    """``out_dir`` as a Path, if a session can be written there: not a file, not a folder
    that holds a session already (a session is never overwritten), its parent existing.

    Raises:
        UsageError: naming the folder and what is wrong.
        OutputError: the folder cannot be written.
    """
    out_dir = check_parent_exists(Path(out_dir), "--out")
    if out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f"--out {str(out_dir)!r} exists and is not a folder")
    if (out_dir / SESSION_NAME).exists() or any(out_dir.glob(EPISODE_GLOB)):
        raise UsageError(f"--out {str(out_dir)!r} already holds a deployment session; choose "
                         "another folder (a session log is never overwritten)")
    check_writable_dir(out_dir, "--out folder")
    return out_dir


class SessionLogWriter:
    """Writes a session folder (module docstring): ``session.json`` at once (status
    ``running``), each episode's file when it ends, the final status at :meth:`close`.

    With ``background`` (a real robot: its servo's watchdog must keep getting targets while a
    file goes to disk), each episode is written by a thread while the session goes on; the
    next write and :meth:`close` wait for it and raise its error.

    Raises:
        UsageError, OutputError: as :func:`check_session_folder`.
    """

    def __init__(self, out_dir: Path | str, header: Mapping[str, Any],
                 background: bool = False) -> None:
        self.out_dir = check_session_folder(out_dir)
        make_dirs(self.out_dir)
        self.background = background
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.document: dict[str, Any] = {
            "format": SESSION_FORMAT, **dict(header), "status": "running", "reason": None,
            "started": now_iso(), "ended": None, "episodes": [],
            "provenance": {"versions": package_versions(), "git_commit": git_commit()}}
        self._write_document()

    def _write_document(self) -> None:
        atomic_write_json(self.out_dir / SESSION_NAME, self.document)

    def _write(self, path: Path, arrays: dict[str, np.ndarray], line: dict[str, Any]) -> None:
        try:
            atomic_write(path, lambda stream: _save_npz(stream, arrays))
            self.document["episodes"].append(line)
            self._write_document()
        except BaseException as err:
            if not self.background:
                raise
            self._error = err

    def write_episode(self, recorder: EpisodeRecorder) -> Path:
        """Write the episode's file atomically, then ``session.json`` naming it."""
        path = self.out_dir / episode_name(recorder.episode)
        arrays, line = recorder.arrays(), recorder.summary()
        self.wait()
        if not self.background:
            self._write(path, arrays, line)
            return path
        self._thread = threading.Thread(target=self._write, args=(path, arrays, line),
                                        name="session-log")
        self._thread.start()
        return path

    def wait(self) -> None:
        """Wait for the episode being written in the background; raise its error."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def close(self, status: str, reason: str | None = None) -> Path:
        """Write the final ``status`` (and its ``reason``) once every episode is written;
        returns ``session.json``'s path (a failed background write: ``failed``, then its
        error is raised)."""
        if status not in STATUSES:
            raise UsageError(f"session status {status!r} is not one of {list(STATUSES)}")
        error: BaseException | None = None
        try:
            self.wait()
        except Exception as err:
            error, status = err, "failed"
            reason = f"writing an episode failed: {err}" + (f"; {reason}" if reason else "")
        self.document.update(status=status, reason=reason, ended=now_iso())
        self._write_document()
        if error is not None:
            raise error
        return self.out_dir / SESSION_NAME


# ------------------------------------------------------------------------------- reading
@dataclass
class SessionEpisode:
    """One episode file of a session, read back (its arrays by the module docstring's keys)."""

    path: Path
    arrays: dict[str, np.ndarray]

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def shadow(self) -> bool:
        """Whether a real robot ran beside the simulator (shadow mode)."""
        return "robot_q_rad" in self.arrays

    @property
    def end(self) -> str:
        return str(self.arrays["end"])

    @property
    def decisions(self) -> int:
        return int(self.arrays["q_command_rad"].shape[0])

    def intervention_fraction(self) -> dict[str, float]:
        """The share of decisions the filter answered with each action other than ``pass``
        (0.0 for an episode without decisions)."""
        actions = self.arrays["filter_action"]
        total = max(len(actions), 1)
        return {action: float(np.count_nonzero(actions == action)) / total
                for action in FILTER_ACTIONS if action != "pass"}


@dataclass
class SessionLog:
    """A session read back: its ``session.json`` and its episodes (in order)."""

    path: Path
    header: dict[str, Any]
    episodes: list[SessionEpisode]

    @property
    def label(self) -> str:
        """A name for its figures: the folder's name."""
        return self.path.name or "session"


def is_session(path: Path | str) -> bool:
    """Whether ``path`` is a session folder, its ``session.json`` or one of its episode
    files (a ``session.json`` beside it)."""
    path = Path(path)
    if path.is_dir():
        return (path / SESSION_NAME).is_file()
    if path.name == SESSION_NAME:
        return path.is_file()
    return bool(_EPISODE_NAME.fullmatch(path.name)) and (path.parent / SESSION_NAME).is_file()


def _read_header(path: Path) -> dict[str, Any]:
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DataError(f"{str(path)!r}: not a readable session log ({err})") from err
    if not isinstance(header, dict) or header.get("format") != SESSION_FORMAT:
        found = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise DataError(f"{str(path)!r}: not a deployment session log (format {found!r}, "
                        f"expected {SESSION_FORMAT!r})")
    return header


def read_episode(path: Path | str) -> SessionEpisode:
    """One episode file.

    Raises:
        DataError: the file is missing, damaged or lacks a key (naming it).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(f"{str(path)!r}: not a readable session episode "
                        f"({type(err).__name__}: {err})") from err
    needed = (*REQUIRED_KEYS, *SHADOW_KEYS) if "robot_q_rad" in arrays else REQUIRED_KEYS
    missing = [key for key in needed if key not in arrays]
    if missing:
        raise DataError(f"{str(path)!r}: not a session episode (no {', '.join(missing)})")
    return SessionEpisode(path=path, arrays=arrays)


def read_session(path: Path | str) -> SessionLog:
    """A session: its folder or ``session.json`` (every episode ``session.json`` lists), or
    one episode file (that episode alone, with its folder's ``session.json``).

    Raises:
        DataError: no session there, a damaged file, or an episode the log lists missing.
    """
    path = Path(path)
    if not is_session(path):
        raise DataError(f"{str(path)!r}: no deployment session log there ({SESSION_NAME} and "
                        "episode-NNNN.npz, written by `rehabbot deploy`)")
    folder = path if path.is_dir() else path.parent
    header = _read_header(folder / SESSION_NAME)
    if _EPISODE_NAME.fullmatch(path.name):
        return SessionLog(path=folder, header=header, episodes=[read_episode(path)])
    listed = header.get("episodes")
    if not isinstance(listed, list):
        raise DataError(f"{str(folder / SESSION_NAME)!r}: its 'episodes' is not a list")
    files = []
    for line in listed:
        name = line.get("file") if isinstance(line, dict) else None
        if not isinstance(name, str) or not _EPISODE_NAME.fullmatch(name):
            raise DataError(f"{str(folder / SESSION_NAME)!r}: a bad episode entry {line!r}")
        files.append(folder / name)
    return SessionLog(path=folder, header=header, episodes=[read_episode(f) for f in files])
