"""Clinical evaluation of a policy (``rehabbot evaluate MODEL|expert|random``).

Each episode starts from ``reset(seed=seed + k)`` and runs the policy deterministically until
the episode ends (success, safety termination or the 1000-step limit). Per episode it records
the return, success, length, the steps to finish (length of a successful episode), the safety
rule that ended it, the peak cuff force, and the kinematic quality of the robot's motion from
:func:`rehabbot.analysis.metrics.kinematic_summary`: peak joint speed, RMS and peak joint
acceleration, peak joint jerk (finite differences at the env's ``dt``), SPARC, log
dimensionless jerk and normalised jerk of the tool's (the patient's hand's or foot's) speed
profile, and the peak actuator torque of each joint. From the patient's side
(:mod:`rehabbot.sim.patient_drive`): the robot's and the patient's work on the limb, the
assistance ratio (the robot's share of the positive work), the peak muscle torque, and the range
of motion achieved versus prescribed (:func:`range_of_motion_deg`).

Outputs, for each policy, in ``OUT/<label>/``:

=================== =========================================================================
``evaluation.json`` the summary (mean ± std over episodes), every episode's figures, the seeds,
                    the policy's provenance and the package versions
``trace.npz``       the first episode step by step (:mod:`rehabbot.analysis.traces`), read by
                    ``rehabbot plot`` for the paper's Figs. 3, 5 and 6 and the patient-side
                    Figs. 7-9
``patients.md``     with several patients (a population env): one row per patient
=================== =========================================================================

With several policies, ``OUT/comparison.md`` holds their summaries side by side (and their
per-patient tables). Every episode's figures name its patient (``"patient"``: index in the
population, profile, condition), and ``"per_patient"`` averages each patient's episodes.
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.analysis.evaluation_folders import (
    COMPARISON_NAME,
    PATIENTS_NAME,
    REPORT_NAME,
    check_label_folders,
    lock_run_folders,
)
from rehabbot.analysis.metrics import kinematic_summary
from rehabbot.analysis.patient_records import (
    format_patient_table,
    patient_record,
    per_patient_summary,
)
from rehabbot.analysis.policy_specs import (
    CUSTOM_KIND,
    PolicySpec,
    check_distinct_labels,
    describe_spec,
    is_named_spec,
    resolve_policy,
)
from rehabbot.analysis.quiet import make_env, quiet_known_warnings
from rehabbot.analysis.range_of_motion import (
    BEYOND_PRESCRIBED,
    achieved_fraction,
    beyond_prescribed,
    range_of_motion_deg,
)
from rehabbot.analysis.recorder import WorkRecorder, patient_limits
from rehabbot.analysis.traces import TRACE_NAME, load_trace, save_trace_file, trace_from_episode
from rehabbot.common.errors import DataError, OutputError, UsageError
from rehabbot.common.files import atomic_save_all, atomic_write_text
from rehabbot.common.provenance import package_versions
from rehabbot.common.text_tables import markdown_table
from rehabbot.rl import runs
from rehabbot.rl.policies import LoadedPolicy, PolicyError, env_for
from rehabbot.rl.rollout import Episode, run_episode
from rehabbot.sim.physics import RULES

SUMMARY_METRICS = (
    # key in the summary, label in the table, unit
    ("return", "return", ""),
    ("success_rate", "success rate", "%"),
    ("length", "episode length", "steps"),
    ("steps_to_finish", "steps to finish", "steps"),
    ("peak_cuff_force_n", "peak cuff force", "N"),
    ("peak_joint_speed_rad_s", "peak joint speed", "rad/s"),
    ("rms_joint_acceleration_rad_s2", "RMS joint acceleration", "rad/s²"),
    ("peak_joint_acceleration_rad_s2", "peak joint acceleration", "rad/s²"),
    ("peak_joint_jerk_rad_s3", "peak joint jerk", "rad/s³"),
    ("sparc", "SPARC (tool speed)", ""),
    ("ldlj", "LDLJ (tool speed)", ""),
    ("normalized_jerk", "normalised jerk (tool)", ""),
    ("peak_torque_nm", "peak robot torque", "N·m"),
    ("robot_work_j", "robot work on the limb", "J"),
    ("patient_work_j", "patient work on the limb", "J"),
    ("assistance_ratio", "assistance ratio", ""),
    ("peak_patient_torque_nm", "peak patient torque", "N·m"),
    ("rom_achieved_fraction", "ROM achieved / prescribed", ""),
)
# The muscles' figures: episodes of MyoSuite's legs only (patient_model="myo"); a report
# and its table have them when its episodes do.
MUSCLE_METRICS = (
    ("muscle_work_j", "muscle work on the limb", "J"),
    ("peak_muscle_force_n", "peak muscle force", "N"),
    ("mean_muscle_activation", "mean muscle activation", ""),
    ("mean_muscle_excitation", "mean muscle excitation", ""),
)
DEFAULT_EPISODES = 10


def episode_figures(episode: Episode) -> dict[str, Any]:
    """The JSON-ready figures of one episode: outcome, cuff force and motion quality."""
    figures = {
        "seed": episode.seed,
        "exercise": episode.exercise,
        "weight_level": episode.weight_level,
        "return": episode.total_return,
        "length": episode.length,
        "success": episode.success,
        "steps_to_finish": episode.length if episode.success else None,
        "targets_reached": episode.targets_reached,
        "num_targets": episode.num_targets,
        "safety_violation": episode.safety_violation,
        "truncated": episode.truncated,
        "peak_cuff_force_n": float(np.max(episode.interaction_force_n)),
    }
    achieved, prescribed = range_of_motion_deg(episode.patient_qpos_rad,
                                               episode.target_patient_deg)
    figures.update({
        "robot_work_j": episode.robot_work_j,
        "patient_work_j": episode.patient_work_j,
        "assistance_ratio": (episode.assistance_ratio if math.isfinite(episode.assistance_ratio)
                             else None),
        "peak_patient_torque_nm": float(np.max(np.abs(episode.patient_torque_nm))),
        "rom_achieved_deg": achieved.tolist(),
        "rom_prescribed_deg": prescribed.tolist(),
        "rom_achieved_fraction": achieved_fraction(achieved, prescribed),
    })
    if episode.muscle_work_j is not None:
        figures.update({key: getattr(episode, key) for key, _label, _unit in MUSCLE_METRICS})
    figures.update(kinematic_summary(episode.robot_qpos_rad, episode.dt_s,
                                     tool_m=episode.tool_pos_m,
                                     torque_nm=episode.robot_torque_nm))
    return figures


def _mean_std(values: Sequence[float | None]) -> tuple[float | None, float | None]:
    finite = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not finite:
        return None, None
    return float(np.mean(finite)), float(np.std(finite))


def summarize(episodes: list[dict]) -> dict:
    """Mean ± std over episodes of every figure, the success rate, safety counts by rule."""
    summary: dict[str, Any] = {"episodes": len(episodes)}
    summary["success_rate"] = float(np.mean([e["success"] for e in episodes]))
    for key, _label, _unit in SUMMARY_METRICS:
        if key == "success_rate":
            continue
        mean, std = _mean_std([e.get(key) for e in episodes])
        summary[key] = {"mean": mean, "std": std}
    if any("muscle_work_j" in e for e in episodes):
        for key, _label, _unit in MUSCLE_METRICS:
            mean, std = _mean_std([e.get(key) for e in episodes])
            summary[key] = {"mean": mean, "std": std}
    counts = dict.fromkeys(RULES, 0)
    for episode in episodes:
        if episode["safety_violation"] is not None:
            counts[episode["safety_violation"]] += 1
    summary["safety_terminations"] = counts
    summary["truncated"] = sum(e["truncated"] for e in episodes)
    summary["max_peak_cuff_force_n"] = max(e["peak_cuff_force_n"] for e in episodes)
    per_joint = np.array([e["peak_torque_per_joint_nm"] for e in episodes])
    summary["peak_torque_per_joint_nm"] = per_joint.max(axis=0).tolist()
    return summary


# A policy's label names its output folder: letters, digits, ".", "_" and "-" only, so that
# a label built from a file's contents (a manifest's seed, a zoo file's algorithm) can never
# name a path elsewhere.
LABEL_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


def check_label(label: Any) -> str:
    """``label`` if it is a safe folder name, else :class:`DataError` naming it."""
    if not isinstance(label, str) or not LABEL_RE.match(label) or ".." in label:
        raise DataError(f"policy label {label!r} is not a safe folder name (letters, digits, "
                        "'.', '_' and '-' only); it was built from a file's contents")
    return label


def label_dir(out_dir: Path, label: Any) -> Path:
    """``out_dir/<label>``, the output folder of one policy (:func:`check_label`)."""
    return Path(out_dir) / check_label(label)


def check_custom_label(label: str) -> str:
    """``label`` of a custom policy if it is a safe folder name, else :class:`UsageError`."""
    if not LABEL_RE.match(label) or ".." in label:
        raise UsageError(f"policy label {label!r} is not a safe folder name (letters, digits, "
                         "'.', '_' and '-' only, at most 100); set the policy's `label` "
                         "attribute to one")
    return label


def run_env_for(specs: Sequence[PolicySpec], env_id: str | None,
                env_kwargs: dict | None) -> tuple[str, dict]:
    """:func:`rehabbot.rl.policies.env_for` of the named specs (custom policies cannot name
    an env: with only those, ``env_id`` is required)."""
    named = [str(spec) for spec in specs if is_named_spec(spec)]
    if not named and env_id is None:
        raise UsageError(f"{', '.join(describe_spec(s) for s in specs)}: give the env to run "
                         "in (env_id=..., --env ENV)")
    return env_for(named, env_id, env_kwargs)


class Evaluator:
    """The env and the policies of one evaluation, every policy loaded and checked against the
    env, before any episode runs (:func:`open_evaluator`); :meth:`run` runs them. A context
    manager: leaving it closes the env."""

    def __init__(self, env_id: str, env_kwargs: dict, env: WorkRecorder,
                 policies: list[LoadedPolicy], seed: int, deterministic: bool) -> None:
        self.env_id = env_id
        self.env_kwargs = env_kwargs
        self.env = env
        self.policies = policies
        self.seed = seed
        self.deterministic = deterministic

    @property
    def labels(self) -> list[str]:
        """The policies' labels, in the order given (each names its output folder)."""
        return [policy.label for policy in self.policies]

    def run(self, episodes: int = DEFAULT_EPISODES) -> list[tuple[dict, dict]]:
        """Every policy on episodes seeded ``seed``, ``seed + 1``, ...; returns each one's
        report (JSON-ready) and first episode's trace (see :func:`evaluate_policies`)."""
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
            raise UsageError(f"episodes={episodes!r} must be an integer >= 1")
        env, seed = self.env, self.seed
        results = []
        for policy in self.policies:
            started = time.perf_counter()
            figures, trace = [], None
            for k in range(episodes):
                episode = run_episode(env, policy, seed + k, self.deterministic)
                patient = patient_record(env)
                figures.append({**episode_figures(episode), "patient": patient})
                if trace is None:
                    trace = {**trace_from_episode(episode), **env.series(),
                             **patient_limits(env), "patient": np.array(patient["description"])}
            report = {
                "env_id": self.env_id,
                "env_kwargs": self.env_kwargs,
                "policy": policy.describe(),
                "seed": seed,
                "episode_seeds": [seed + k for k in range(episodes)],
                "deterministic": self.deterministic,
                "summary": summarize(figures),
                "per_patient": per_patient_summary(figures),
                "per_episode": figures,
                "wall_clock_s": time.perf_counter() - started,
                "versions": package_versions(),
            }
            results.append((report, trace))
        return results

    def close(self) -> None:
        """Close the env."""
        self.env.close()

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def _resolve(spec: PolicySpec, env: WorkRecorder, seed: int) -> LoadedPolicy:
    """:func:`.policy_specs.resolve_policy`; a policy that ends the program while it is
    imported or built (``SystemExit``) is a :class:`PolicyError` naming it."""
    try:
        policy = resolve_policy(spec, env, seed=seed)
    except SystemExit as err:
        raise PolicyError(f"policy {describe_spec(spec)}: loading it called exit({err.code!r}); "
                          "a policy must not end the program") from err
    if policy.spec is None and isinstance(spec, str):
        policy.spec = spec
    return policy


def open_evaluator(specs: Sequence[PolicySpec], env_id: str | None = None,
                   env_kwargs: dict | None = None, seed: int = 0,
                   deterministic: bool = True) -> Evaluator:
    """Make the env and load and check every policy of ``specs`` (see
    :func:`evaluate_policies`), running nothing yet: the labels are known and a bad spec has
    failed before the caller picks an output folder. Close it (``with``) when done."""
    if isinstance(specs, str) or not isinstance(specs, Sequence):
        raise UsageError(f"specs={specs!r} must be a list of policies (e.g. ['expert'])")
    env_id, kwargs = run_env_for(specs, env_id, env_kwargs)
    env = WorkRecorder(make_env(env_id, **kwargs))
    try:
        with quiet_known_warnings():
            policies = [_resolve(spec, env, seed) for spec in specs]
        for policy in policies:  # before any episode runs
            if policy.kind == CUSTOM_KIND:
                check_custom_label(policy.label)
            else:
                check_label(policy.label)
        check_distinct_labels(policies)
        zoo = [p.label for p in policies if p.kind == "zoo"]
        if zoo and not deterministic:
            raise UsageError(f"{', '.join(zoo)}: zoo agents are deterministic only (their "
                             "exploration noise is not exported); leave out --stochastic")
    except BaseException:
        env.close()
        raise
    return Evaluator(env_id, kwargs, env, policies, seed, deterministic)


def evaluate_policies(specs: Sequence[PolicySpec], env_id: str | None = None,
                      episodes: int = DEFAULT_EPISODES, seed: int = 0,
                      env_kwargs: dict | None = None,
                      deterministic: bool = True) -> list[tuple[dict, dict]]:
    """Evaluate several policies on the same episodes of one env; returns each one's report
    (JSON-ready) and first episode's trace.

    A policy is a name (``"expert"``, ``"aan"``, ``"random"``, a model path, a zoo agent
    ``"zoo:ENV/ALGO"``), a ``"module:attr"`` string, any object with SB3's
    ``predict(obs, deterministic=...) -> (action, state)``, or a class or factory that
    takes the env and returns one (``AssistAsNeeded``, ``lambda env: MyPolicy(env)``); see
    :mod:`rehabbot.analysis.policy_specs`. A custom policy is labelled by its ``label``
    attribute, else its class name.

    ``env_id`` may be None when a model of a ``rehabbot train`` run or a zoo agent is among
    ``specs`` (its manifest's or zoo file's id and env kwargs are used). Every spec is
    loaded and checked against the env before the first episode runs, so a bad one fails
    before any work is done. Each episode's figures name its patient (``"patient"``: a
    population env draws one per episode), and ``"per_patient"`` tabulates them.

    Raises:
        PolicyError: a policy failed to load, or while it ran (an exception or ``exit()`` in
            its ``predict``, an action that is not a finite array of the action space, a
            result that is not ``(action, state)``), naming it.
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise UsageError(f"episodes={episodes!r} must be an integer >= 1")
    with open_evaluator(specs, env_id, env_kwargs, seed, deterministic) as evaluator:
        return evaluator.run(episodes)


def evaluate(spec: PolicySpec, env_id: str | None = None, episodes: int = DEFAULT_EPISODES,
             seed: int = 0, env_kwargs: dict | None = None,
             deterministic: bool = True) -> tuple[dict, dict]:
    """Evaluate one policy (:func:`evaluate_policies`); returns its report and trace."""
    return evaluate_policies([spec], env_id, episodes, seed, env_kwargs, deterministic)[0]


# --------------------------------------------------------------------------- output


def save_report(report: dict, trace: dict, out_dir: Path) -> tuple[Path, Path]:
    """``out_dir/evaluation.json`` and ``out_dir/trace.npz``, written as a pair: both go to
    temporary names, are read back (the JSON parsed, the trace loaded and its shapes
    checked) and only then renamed, so a failure (a full disk) raises
    :class:`~rehabbot.common.errors.OutputError` and leaves the earlier pair as it was,
    never a new report beside an old trace."""
    out_dir = _real_folder(out_dir)
    json_path, trace_path = out_dir / REPORT_NAME, out_dir / TRACE_NAME
    atomic_save_all(
        {json_path: lambda name: save_report_file(name, report),
         trace_path: lambda name: save_trace_file(name, trace)},
        {json_path: lambda tmp: json.loads(Path(tmp).read_text(encoding="utf-8")),
         trace_path: load_trace},
    )
    return json_path, trace_path


def _real_folder(folder: Path) -> Path:
    """``folder``, created (with its parents) if missing; a symbolic link is refused, never
    written through.

    Raises:
        OutputError: ``folder`` is a symbolic link (naming it and its target).
    """
    folder = Path(folder)
    if folder.is_symlink():
        raise OutputError(f"refusing to write into {folder}: it is a symbolic link (to "
                          f"{os.readlink(folder)}); remove the link or choose another folder")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def save_report_file(name: str | Path, report: dict) -> None:
    """Write ``report`` as indented JSON to the file ``name`` as it is (no temporary)."""
    text = json.dumps(report, indent=2, default=_json_default) + "\n"
    Path(name).write_text(text, encoding="utf-8")


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _cell(stat: Any, key: str) -> str | None:
    if key == "success_rate":
        return f"{100 * stat:.0f} %"
    mean, std = stat["mean"], stat["std"]
    if mean is None:
        return None
    digits = 0 if abs(mean) >= 100 else (2 if abs(mean) >= 1 else 3)
    text = f"{mean:.{digits}f} ± {std:.{digits}f}"
    if key == "rom_achieved_fraction" and beyond_prescribed(mean):
        text += f" ⚠ {BEYOND_PRESCRIBED}"
    return text


def format_table(reports: Sequence[dict]) -> str:
    """A Markdown table, one column per policy (mean ± std over episodes). A range of motion
    achieved / prescribed above 1 (the limb went beyond the prescription) is flagged in its
    cell: ``1.46 ± 0.02 ⚠ beyond the prescribed range``."""
    header = ["metric"] + [r["policy"]["label"] for r in reports]
    rows = []
    metrics = list(SUMMARY_METRICS)
    if any("muscle_work_j" in r["summary"] for r in reports):
        metrics += MUSCLE_METRICS
    for key, label, unit in metrics:
        name = f"{label} [{unit}]" if unit and unit != "%" else label
        rows.append([name] + [_cell(r["summary"][key], key) if key in r["summary"] else None
                              for r in reports])
    rules = reports[0]["summary"]["safety_terminations"]
    for rule in rules:
        rows.append([f"safety stops: {rule}"]
                    + [str(r["summary"]["safety_terminations"][rule]) for r in reports])
    rows.append(["episodes (seeds)"] + [
        f"{r['summary']['episodes']} ({r['episode_seeds'][0]}..{r['episode_seeds'][-1]})"
        for r in reports])
    return markdown_table(header, rows)


def has_several_patients(report: dict) -> bool:
    """Whether the report's episodes met more than one patient (a population env)."""
    return len(report.get("per_patient", ())) > 1


def format_patient_tables(reports: Sequence[dict]) -> str:
    """Per policy, a heading and its per-patient table
    (:func:`.patient_records.format_patient_table`); empty when every report met one patient
    only."""
    parts = [f"### {r['policy']['label']}: per patient\n\n{format_patient_table(r)}"
             for r in reports if has_several_patients(r)]
    return "\n\n".join(parts)


def write_patient_table(out_dir: Path, report: dict) -> Path | None:
    """``out_dir/patients.md``: the report's per-patient table, when it met several patients
    (None, and no file, otherwise)."""
    if not has_several_patients(report):
        return None
    path = _real_folder(out_dir) / PATIENTS_NAME
    atomic_write_text(path, format_patient_table(report) + "\n")
    return path


def write_comparison(out_dir: Path, reports: Sequence[dict]) -> Path:
    """``out_dir/comparison.md``: the reports' table side by side."""
    path = Path(out_dir) / COMPARISON_NAME
    patients = format_patient_tables(reports)
    atomic_write_text(path, format_table(reports) + "\n" + (f"\n{patients}\n" if patients
                                                             else ""))
    return path


def ensure_trace(run_dir: Path, seed: int | None = None) -> Path:
    """The trace of one deterministic episode of a training run's final model, evaluated now
    if ``<run_dir>/evaluation/<label>/trace.npz`` does not exist yet."""
    run_dir = Path(run_dir)
    existing = sorted((run_dir / runs.EVALUATION_DIR).glob(f"*/{TRACE_NAME}"))
    if existing:
        return existing[0]
    manifest = runs.read_manifest(run_dir) or {}
    if seed is None:
        seed = manifest.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise DataError(f"{run_dir / runs.MANIFEST_NAME}: seed {seed!r} is not an integer "
                            ">= 0")
    with lock_run_folders(run_dir):  # never into the folder of a run being trained
        report, trace = evaluate(str(run_dir / runs.MODEL_NAME), None, episodes=1, seed=seed)
        folder = label_dir(run_dir / runs.EVALUATION_DIR, report["policy"]["label"])
        check_label_folders(run_dir / runs.EVALUATION_DIR, [report["policy"]["label"]])
        _json, trace_path = save_report(report, trace, folder)
    return trace_path
