"""Evaluated episodes on disk: ``trace.npz``, one episode step by step, written by
``rehabbot evaluate`` and read by ``rehabbot plot`` (the paper's Figs. 3, 5 and 6).

======================== ==================================================================
key                      what
======================== ==================================================================
``env_id``, ``policy``   the env id and the policy's label
``seed``, ``dt_s``       the episode's reset seed and the decision period [s]
``time_s``               (T + 1,) time of each row [s] (row 0: after ``reset``)
``robot_qpos_rad``       (T + 1, n) robot joint angles
``robot_torque_nm``      (T + 1, n) robot actuator torques
``torque_limit_nm``      (n,) the robot's torque limits
``joint_names``          (n,) the robot's joint names
``tool_pos_m``           (T + 1, 3 k) tool (flange) position of each of the k robots, each in
                         its own robot base frame (k = 2 in the bilateral env, right first)
``target_tool_pos_m``    (N, 3 k) every target's tool positions p*, the same frames
``target_robot_rad``     (N, n) every target's joint angles theta*
``target_index``         (T + 1,) the active target
``patient_qpos_rad``     (T + 1, 3) the patient's exercised joints
``interaction_force_n``  (T + 1,) the cuff force
``target_patient_deg``   (N, 3) the exercised joints' angles at every target (the prescribed
                         path)
``patient_joint_names``  (3,) the exercised joints
``patient_range_deg``    (3, 2) their ranges of motion (after a condition's ``rom_scale``)
``cuff_force_limit_n``   the cuff's force limit (the safety rule's)
``robot_work_j``,        (T + 1,) the robot's and the patient's work on the limb since the
``patient_work_j``       reset [J]
``patient``              who was in the chair: ``"female, 1.6 m, 55 kg; MAS 3 spasticity"``
``safety_violation``     the safety rule that stopped the episode (empty: none did)
``robot_name``           the robot (``"ur5e"``, ``"fr3"``)
``*_source``             where each limit comes from: ``torque_limit_source``,
                         ``cuff_force_limit_source``, ``patient_range_source``
======================== ==================================================================

The patient-side keys (from ``target_patient_deg`` on) are optional: traces written before
them load with those fields None, and the figures say what is missing ("patient not
recorded").
"""

from __future__ import annotations

import re
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rehabbot.common.files import atomic_write
from rehabbot.envs.registration import env_short_name
from rehabbot.rl.rollout import Episode

TRACE_NAME = "trace.npz"
TRACE_KEYS = ("env_id", "policy", "seed", "dt_s", "time_s", "robot_qpos_rad", "robot_torque_nm",
              "torque_limit_nm", "joint_names", "tool_pos_m", "target_tool_pos_m",
              "target_robot_rad", "target_index", "patient_qpos_rad", "interaction_force_n",
              "target_patient_deg", "patient_joint_names", "patient_range_deg",
              "cuff_force_limit_n", "robot_work_j", "patient_work_j", "patient",
              "safety_violation", "robot_name", "torque_limit_source", "cuff_force_limit_source",
              "patient_range_source")
# optional keys read into :class:`Trace` (None when absent): key -> dtype
PATIENT_KEYS: dict[str, type] = {
    "patient_qpos_rad": float, "interaction_force_n": float, "target_index": int,
    "target_patient_deg": float, "patient_joint_names": str, "patient_range_deg": float,
    "cuff_force_limit_n": float, "robot_work_j": float, "patient_work_j": float}
# optional text keys read into :class:`Trace` as a str (None when absent)
TEXT_KEYS: tuple[str, ...] = ("patient", "safety_violation", "robot_name", "torque_limit_source",
                              "cuff_force_limit_source", "patient_range_source")
NOT_RECORDED = "not recorded (evaluated with an earlier rehabbot)"
REQUIRED_KEYS: tuple[str, ...] = (
    "env_id", "policy", "dt_s", "time_s", "robot_qpos_rad", "robot_torque_nm",
    "torque_limit_nm", "joint_names", "tool_pos_m", "target_tool_pos_m",
)


@dataclass
class Trace:
    """One evaluated episode (``trace.npz``)."""

    path: Path
    env_id: str
    policy: str
    dt_s: float
    time_s: np.ndarray
    robot_qpos_rad: np.ndarray
    robot_torque_nm: np.ndarray
    torque_limit_nm: np.ndarray
    joint_names: list[str]
    tool_pos_m: np.ndarray
    target_tool_pos_m: np.ndarray
    patient_qpos_rad: np.ndarray | None = None
    interaction_force_n: np.ndarray | None = None
    target_index: np.ndarray | None = None
    target_patient_deg: np.ndarray | None = None
    patient_joint_names: np.ndarray | None = None
    patient_range_deg: np.ndarray | None = None
    cuff_force_limit_n: np.ndarray | None = None
    robot_work_j: np.ndarray | None = None
    patient_work_j: np.ndarray | None = None
    seed: int | None = None
    patient: str | None = None
    safety_violation: str | None = None  # None: no rule stopped the episode (or not recorded)
    robot_name: str | None = None
    torque_limit_source: str | None = None
    cuff_force_limit_source: str | None = None
    patient_range_source: str | None = None

    @property
    def label(self) -> str:
        """``<policy>_<env-short>``, safe as part of a file name."""
        return sanitize(f"{self.policy}_{env_short_name(self.env_id)}")

    @property
    def patient_text(self) -> str:
        """Who was in the chair, for a figure's title."""
        return self.patient or NOT_RECORDED

    @property
    def stop_time_s(self) -> float | None:
        """When a safety rule stopped the episode (its last row), None if none did."""
        return float(self.time_s[-1]) if self.safety_violation else None


def sanitize(text: str) -> str:
    """Keep letters, digits, ``.``, ``_`` and ``-``; anything else becomes ``-``."""
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.")
    return cleaned or "unnamed"


def check_exists(paths: Sequence[Path | str]) -> list[Path]:
    result = []
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise ValueError(f"{path}: no such file or directory")
        result.append(path)
    return result


def find_files(paths: Sequence[Path | str], name: str) -> list[Path]:
    """Files called ``name`` at or below each path (a path may also be the file itself)."""
    found: dict[Path, None] = {}
    for path in check_exists(paths):
        if path.is_file():
            candidates: Iterable[Path] = [path] if path.name == name else []
        else:
            candidates = sorted(path.rglob(name))
        for candidate in candidates:
            found.setdefault(candidate.resolve(), None)
    return list(found)


def find_traces(paths: Sequence[Path | str]) -> list[Path]:
    """All ``trace.npz`` files at or below ``paths`` (sorted per path, without duplicates).

    Raises:
        ValueError: a path does not exist.
    """
    return find_files(paths, TRACE_NAME)


def _str_item(value: np.ndarray) -> str:
    return str(np.asarray(value).reshape(-1)[0]) if np.size(value) else ""


def _rows_of_points(value: np.ndarray) -> np.ndarray:
    """Rows of one or more 3-D points (k robots: 3 k columns); a flat array is 3-D points."""
    array = np.asarray(value, dtype=float)
    return array if array.ndim == 2 else array.reshape(-1, 3)


def load_trace(path: Path | str) -> Trace:
    """Read a ``trace.npz`` written by ``rehabbot evaluate``.

    Raises:
        ValueError: the file is missing, corrupt or lacks a required key (names the file).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in REQUIRED_KEYS if key not in data.files]
            if missing:
                raise ValueError(f"missing key(s) {', '.join(missing)}")
            trace = _trace_of(data, data.files, path)
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{path}: not a readable trace.npz ({err})") from err
    return _checked(trace, path)


def trace_from_arrays(arrays: Mapping[str, np.ndarray]) -> Trace:
    """A :class:`Trace` of the arrays of :func:`trace_from_episode` (e.g. a trace that
    :func:`rehabbot.analysis.evaluation.evaluate_policies` returns), without a file."""
    missing = [key for key in REQUIRED_KEYS if key not in arrays]
    if missing:
        raise ValueError(f"the trace lacks key(s) {', '.join(missing)}")
    return _checked(_trace_of(arrays, list(arrays), Path("<memory>")), Path("<memory>"))


def _trace_of(data: Mapping[str, np.ndarray], keys: Sequence[str], path: Path) -> Trace:
    return Trace(
                path=path,
                env_id=_str_item(data["env_id"]),
                policy=_str_item(data["policy"]),
                dt_s=float(data["dt_s"]),
                time_s=np.asarray(data["time_s"], dtype=float),
                robot_qpos_rad=np.asarray(data["robot_qpos_rad"], dtype=float),
                robot_torque_nm=np.asarray(data["robot_torque_nm"], dtype=float),
                torque_limit_nm=np.asarray(data["torque_limit_nm"], dtype=float).reshape(-1),
                joint_names=[str(name) for name in np.asarray(data["joint_names"]).reshape(-1)],
                tool_pos_m=_rows_of_points(data["tool_pos_m"]),
                target_tool_pos_m=_rows_of_points(data["target_tool_pos_m"]),
                **{key: np.asarray(data[key]).astype(kind) for key, kind in PATIENT_KEYS.items()
                   if key in keys},
                **{key: _str_item(data[key]) or None for key in TEXT_KEYS if key in keys},
                seed=int(np.asarray(data["seed"]).reshape(-1)[0]) if "seed" in keys else None,
            )


def _checked(trace: Trace, path: Path) -> Trace:
    n_steps = len(trace.time_s)
    n_joints = trace.robot_qpos_rad.shape[-1] if trace.robot_qpos_rad.ndim == 2 else -1
    consistent = (
        n_steps >= 1
        and trace.robot_qpos_rad.shape == (n_steps, n_joints)
        and trace.robot_torque_nm.shape == (n_steps, n_joints)
        and len(trace.tool_pos_m) == n_steps
        and trace.tool_pos_m.shape[1] % 3 == 0 and trace.tool_pos_m.shape[1] >= 3
        and trace.target_tool_pos_m.shape[1] == trace.tool_pos_m.shape[1]
        and len(trace.joint_names) == n_joints
        and len(trace.torque_limit_nm) == n_joints
        and trace.dt_s > 0
    )
    if not consistent:
        raise ValueError(f"{path}: not a readable trace.npz (array shapes do not agree)")
    return trace


def trace_from_episode(episode: Episode) -> dict[str, np.ndarray]:
    """The arrays of ``trace.npz`` for one episode."""
    return {
        "env_id": np.array(episode.env_id),
        "policy": np.array(episode.policy),
        "seed": np.array(episode.seed),
        "dt_s": np.array(episode.dt_s),
        "time_s": np.arange(episode.length + 1) * episode.dt_s,
        "robot_qpos_rad": episode.robot_qpos_rad,
        "robot_torque_nm": episode.robot_torque_nm,
        "torque_limit_nm": np.array(episode.torque_limit_nm, dtype=float),
        "joint_names": np.array(episode.joint_names),
        "tool_pos_m": episode.tool_pos_m,
        "target_tool_pos_m": episode.target_tool_pos_m,
        "target_robot_rad": episode.target_robot_rad,
        "target_index": episode.target_index,
        "patient_qpos_rad": episode.patient_qpos_rad,
        "interaction_force_n": episode.interaction_force_n,
        "target_patient_deg": episode.target_patient_deg,
        "safety_violation": np.array(episode.safety_violation or ""),
    }


def save_trace(path: Path, trace: dict[str, np.ndarray]) -> Path:
    """Write ``trace`` (:func:`trace_from_episode`) to ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda stream: np.savez_compressed(stream, **trace))
    return path


def save_trace_file(name: str | Path, trace: dict[str, np.ndarray]) -> None:
    """Write ``trace`` to the file ``name`` as it is (no temporary; callers that need a
    complete-or-absent file use :func:`save_trace` or :func:`.files.atomic_save_all`)."""
    with open(name, "wb") as stream:
        np.savez_compressed(stream, **trace)
