"""Clinical evaluation of a policy: ``rehabbot evaluate MODEL|expert|random --env ENV``.

Each episode starts from ``reset(seed=seed + k)`` and runs the policy deterministically until
the episode ends (success, safety termination or the 1000-step limit). Per episode it records
the return, success, length, the steps to finish (length of a successful episode), the safety
rule that ended it, the peak cuff force, and the kinematic quality of the robot's motion from
:func:`rehabbot.metrics.kinematic_summary`: peak joint speed, RMS and peak joint acceleration,
peak joint jerk (finite differences at the env's ``dt``), SPARC, log dimensionless jerk and
normalised jerk of the tool's (the patient's hand's or foot's) speed profile, and the peak
actuator torque of each joint.

Outputs, for each policy, in ``OUT/<label>/``:

================== ==========================================================================
``evaluation.json`` the summary (mean ± std over episodes), every episode's figures, the seeds,
                    the policy's provenance and the package versions
``trace.npz``       the first episode step by step (:data:`TRACE_KEYS`), read by
                    ``rehabbot plot`` for the paper's Figs. 3, 5 and 6
================== ==========================================================================

With several policies, ``OUT/comparison.md`` holds their summaries side by side.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.training import atomic_write, env_short_name, package_versions, resolve_env_id

TRACE_KEYS = ("env_id", "policy", "seed", "dt_s", "time_s", "robot_qpos_rad", "robot_torque_nm",
              "torque_limit_nm", "joint_names", "tool_pos_m", "target_tool_pos_m",
              "target_robot_rad", "target_index", "patient_qpos_rad", "interaction_force_n")
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
)
DEFAULT_EPISODES = 10


def env_for(spec: str, env_id: str | None, env_kwargs: dict | None) -> tuple[str, dict]:
    """The full env id and kwargs to run ``spec`` in: ``env_id`` if given (with or without
    ``rehabbot/``), else the id and kwargs of the model's ``rehabbot train`` manifest."""
    from rehabbot.policies import PolicyError, find_run_dir, model_file
    from rehabbot.training import resolve_env_id

    kwargs = dict(env_kwargs or {})
    if env_id is None:
        if spec in ("expert", "random"):
            raise ValueError(f"{spec!r} needs --env ENV")
        run_dir = find_run_dir(model_file(spec))
        if run_dir is None:
            raise PolicyError(f"{spec!r} is not in a `rehabbot train` run directory; give --env")
        manifest = json.loads((run_dir / "manifest.json").read_text())
        env_id = manifest["env_id"]
        kwargs = {**manifest.get("env_kwargs", {}), **kwargs}
    return resolve_env_id(env_id), kwargs


# --------------------------------------------------------------------------- one episode


def run_episode(env, policy, seed: int, deterministic: bool = True) -> tuple[dict, dict]:
    """Run one episode; return its figures (JSON-ready) and its step-by-step trace."""
    from rehabbot import env as rehab_env
    from rehabbot.metrics import kinematic_summary
    from rehabbot.models import robot as ur

    base = env.unwrapped
    obs, info = env.reset(seed=seed)
    sequence = base.target_sequence
    qpos, tool, patient, torque, force, index = [], [], [], [], [], []

    def record(observation: np.ndarray, step_info: dict) -> None:
        qpos.append(np.array(observation[rehab_env.THETA], dtype=float))
        tool.append(np.array(observation[rehab_env.P], dtype=float))
        patient.append(np.array(observation[rehab_env.PHI], dtype=float))
        torque.append(np.array(step_info["robot_torque_nm"], dtype=float))
        force.append(float(step_info["interaction_force_n"]))
        index.append(int(step_info["target_index"]))

    record(obs, info)
    total = 0.0
    while True:
        action = policy.act(obs, deterministic=deterministic)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        record(obs, info)
        if terminated or truncated:
            break
    length = len(qpos) - 1
    dt_s = float(base.dt_s)
    trace = {
        "env_id": np.array(env.spec.id if env.spec else "RehabEnv"),
        "policy": np.array(getattr(policy, "label", "policy")),
        "seed": np.array(seed),
        "dt_s": np.array(dt_s),
        "time_s": np.arange(length + 1) * dt_s,
        "robot_qpos_rad": np.array(qpos),
        "robot_torque_nm": np.array(torque),
        "torque_limit_nm": np.array(ur.TORQUE_LIMIT_NM, dtype=float),
        "joint_names": np.array(ur.JOINT_NAMES),
        "tool_pos_m": np.array(tool),
        "target_tool_pos_m": np.array(sequence.tool_pos_base_m, dtype=float),
        "target_robot_rad": np.array(sequence.robot_rad, dtype=float),
        "target_index": np.array(index),
        "patient_qpos_rad": np.array(patient),
        "interaction_force_n": np.array(force),
    }
    success = bool(info["is_success"])
    figures = {
        "seed": seed,
        "exercise": int(info["exercise"]),
        "weight_level": int(info["weight_level"]),
        "return": total,
        "length": length,
        "success": success,
        "steps_to_finish": length if success else None,
        "targets_reached": int(info["target_index"]) + int(success),
        "num_targets": int(info["num_targets"]),
        "safety_violation": info["safety_violation"],
        "truncated": bool(truncated),
        "peak_cuff_force_n": float(np.max(trace["interaction_force_n"])),
    }
    figures.update(kinematic_summary(trace["robot_qpos_rad"], dt_s, tool_m=trace["tool_pos_m"],
                                     torque_nm=trace["robot_torque_nm"]))
    return figures, trace


# --------------------------------------------------------------------------- many episodes


def _mean_std(values: Sequence[float | None]) -> tuple[float | None, float | None]:
    finite = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not finite:
        return None, None
    return float(np.mean(finite)), float(np.std(finite))


def summarize(episodes: list[dict]) -> dict:
    """Mean ± std over episodes of every figure, the success rate, safety counts by rule."""
    from rehabbot.safety import RULES

    summary: dict[str, Any] = {"episodes": len(episodes)}
    summary["success_rate"] = float(np.mean([e["success"] for e in episodes]))
    for key, _label, _unit in SUMMARY_METRICS:
        if key == "success_rate":
            continue
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


def evaluate(spec: str, env_id: str | None = None, episodes: int = DEFAULT_EPISODES,
             seed: int = 0, env_kwargs: dict | None = None,
             deterministic: bool = True) -> tuple[dict, dict]:
    """Evaluate one policy (``"expert"``, ``"random"`` or a model path).

    ``env_id`` may be None for a model of a ``rehabbot train`` run (its manifest's id and env
    kwargs are used). Returns the report (JSON-ready) and the first episode's trace.
    """
    import gymnasium as gym

    import rehabbot  # noqa: F401  (registers the ids)
    from rehabbot.policies import load_policy

    if episodes < 1:
        raise ValueError(f"episodes={episodes!r} must be >= 1")
    env_id, kwargs = env_for(spec, env_id, env_kwargs)
    env = gym.make(env_id, **kwargs)
    try:
        policy = load_policy(spec, env, seed=seed)
        started = time.perf_counter()
        figures, traces = [], None
        for k in range(episodes):
            episode, trace = run_episode(env, policy, seed + k, deterministic)
            figures.append(episode)
            traces = trace if traces is None else traces
        wall_s = time.perf_counter() - started
    finally:
        env.close()
    report = {
        "env_id": env_id,
        "env_kwargs": kwargs,
        "policy": policy.describe(),
        "seed": seed,
        "episode_seeds": [seed + k for k in range(episodes)],
        "deterministic": deterministic,
        "summary": summarize(figures),
        "per_episode": figures,
        "wall_clock_s": wall_s,
        "versions": package_versions(),
    }
    return report, traces


# --------------------------------------------------------------------------- output


def save_report(report: dict, trace: dict, out_dir: Path) -> tuple[Path, Path]:
    """``out_dir/evaluation.json`` and ``out_dir/trace.npz``, each written atomically."""
    json_path, trace_path = out_dir / "evaluation.json", out_dir / "trace.npz"
    out_dir.mkdir(parents=True, exist_ok=True)
    text = json.dumps(report, indent=2, default=_json_default) + "\n"
    atomic_write(json_path, lambda stream: stream.write(text.encode("utf-8")))
    atomic_write(trace_path, lambda stream: np.savez_compressed(stream, **trace))
    return json_path, trace_path


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _cell(stat: Any, key: str) -> str:
    if key == "success_rate":
        return f"{100 * stat:.0f} %"
    mean, std = stat["mean"], stat["std"]
    if mean is None:
        return "-"
    digits = 0 if abs(mean) >= 100 else (2 if abs(mean) >= 1 else 3)
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def format_table(reports: Sequence[dict]) -> str:
    """A Markdown table, one column per policy (mean ± std over episodes)."""
    header = ["metric"] + [r["policy"]["label"] for r in reports]
    rows = []
    for key, label, unit in SUMMARY_METRICS:
        name = f"{label} [{unit}]" if unit and unit != "%" else label
        rows.append([name] + [_cell(r["summary"][key], key) for r in reports])
    rules = reports[0]["summary"]["safety_terminations"]
    for rule in rules:
        rows.append([f"safety stops: {rule}"]
                    + [str(r["summary"]["safety_terminations"][rule]) for r in reports])
    rows.append(["episodes (seeds)"] + [
        f"{r['summary']['episodes']} ({r['episode_seeds'][0]}..{r['episode_seeds'][-1]})"
        for r in reports])
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(str(c).ljust(w) for c, w in zip(cells, widths, strict=True)) + " |"

    separator = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([line(header), separator, *(line(r) for r in rows)])


def default_out_dir(specs: Sequence[str], env_id: str | None) -> Path:
    """``<run>/evaluation`` for models of one training run, else ``runs/evaluation/<env>``."""
    from rehabbot.policies import find_run_dir, model_file

    runs = set()
    for spec in specs:
        if spec in ("expert", "random"):
            continue
        run_dir = find_run_dir(model_file(spec))
        runs.add(run_dir)
    if len(runs) == 1 and None not in runs and len(specs) == 1:
        return runs.pop() / "evaluation"
    return Path("runs") / "evaluation" / (env_short_name(env_id) if env_id else "models")


def ensure_trace(run_dir: Path, seed: int | None = None) -> Path:
    """The trace of one deterministic episode of a training run's final model, evaluated now
    if ``<run_dir>/evaluation/<label>/trace.npz`` does not exist yet."""
    run_dir = Path(run_dir)
    existing = sorted((run_dir / "evaluation").glob("*/trace.npz"))
    if existing:
        return existing[0]
    manifest = json.loads((run_dir / "manifest.json").read_text())
    seed = int(manifest.get("seed", 0)) if seed is None else seed
    report, trace = evaluate(str(run_dir / "model.zip"), None, episodes=1, seed=seed)
    _json, trace_path = save_report(report, trace,
                                    run_dir / "evaluation" / report["policy"]["label"])
    return trace_path


# --------------------------------------------------------------------------- command line


def add_evaluate_parser(commands: argparse._SubParsersAction) -> None:
    """The ``rehabbot evaluate`` subcommand."""
    parser = commands.add_parser(
        "evaluate", help="evaluate trained models, the scripted expert or random actions",
        description=__doc__.split("\n\n")[0] + " Prints a table and writes JSON.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  rehabbot evaluate runs/rehab-reach-v0/sac/seed0/model.zip\n"
               "  rehabbot evaluate expert random --env rehab-reach-v0 --episodes 20\n"
               "  rehabbot evaluate runs/rehab-reach-v0/sac/seed0/model.zip expert random "
               "--out runs/compare\n\n"
               "Each policy's files go to OUT/<label>/evaluation.json and OUT/<label>/trace.npz.")
    parser.add_argument("policies", nargs="+", metavar="MODEL|expert|random",
                        help="a model .zip saved by `rehabbot train` (or any SB3 PPO/SAC/TD3 "
                             "zip), 'expert' (scripted expert) or 'random'")
    parser.add_argument("--env", metavar="ENV",
                        help="env id, with or without 'rehabbot/' (default: the model's run "
                             "manifest; required for expert and random)")
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, metavar="N",
                        help=f"episodes per policy (default: {DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=int, default=0, metavar="S",
                        help="episode k is reset with seed S + k (default: 0)")
    parser.add_argument("--stochastic", action="store_true",
                        help="sample the model's actions instead of using its mean")
    parser.add_argument("--env-kwargs", type=json.loads, default=None, metavar="JSON",
                        help="extra RehabEnv keyword arguments, e.g. '{\"weight_level\": 4}'")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="output folder (default: <run>/evaluation for one model of a "
                             "training run, else runs/evaluation/<env>)")
    parser.set_defaults(func=cmd_evaluate)


def check_writable(folder: Path) -> None:
    """Raise OSError naming ``folder`` unless files can be created in it (made if needed)."""
    folder.mkdir(parents=True, exist_ok=True)
    handle, probe = tempfile.mkstemp(dir=folder, prefix=".write-probe.")
    os.close(handle)
    os.unlink(probe)


def cmd_evaluate(args: argparse.Namespace) -> int:
    from rehabbot.cli import EXIT_USAGE, CliError
    from rehabbot.policies import PolicyError

    if args.episodes < 1:
        raise CliError(f"--episodes {args.episodes} must be >= 1", EXIT_USAGE)
    try:
        env_id = resolve_env_id(args.env) if args.env else None
        out_dir = args.out or default_out_dir(args.policies, env_id)
    except (ValueError, PolicyError) as err:
        raise CliError(str(err), EXIT_USAGE) from err
    try:
        check_writable(out_dir)
    except OSError as err:
        raise CliError(f"cannot write to output folder {str(out_dir)!r}: {err}") from err
    reports = []
    for spec in args.policies:
        try:
            report, trace = evaluate(spec, env_id, args.episodes, args.seed,
                                     args.env_kwargs, deterministic=not args.stochastic)
        except PolicyError as err:
            raise CliError(str(err)) from err
        except ValueError as err:
            raise CliError(str(err), EXIT_USAGE) from err
        json_path, trace_path = save_report(report, trace, out_dir / report["policy"]["label"])
        print(f"{report['policy']['label']}: wrote {json_path} and {trace_path}")
        reports.append(report)
    table = format_table(reports)
    print(f"\n{reports[0]['env_id']}, {args.episodes} episodes per policy\n\n{table}")
    if len(reports) > 1:
        atomic_write(out_dir / "comparison.md",
                     lambda stream: stream.write((table + "\n").encode("utf-8")))
    return 0
