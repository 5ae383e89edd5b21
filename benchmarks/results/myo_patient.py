"""The musculoskeletal patient (MyoSuite's legs and right arm, ``patient_model="myo"``) against
the rigid one: passive knee and elbow torque against angle, the static cuff force along the
seated knee extension, the scripted expert on every exercise of the myo ids, and the
throughput of both in the same run.

    python benchmarks/results/myo_patient.py [--seed 0] [--steps 2000]
        [--page docs/results/myo-patient]

Needs ``pip install "rehabbot[myo]"``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.envs.registration import MYO_VARIANTS
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.sim import build_scene, statics
from rehabbot.sim.muscles import muscle_torque_nm

INTRO = """MyoSuite's legs (`myo-sim` 0.2.3, 80 muscles) seated and lying in RehabBot's scenes,
and its right arm (63 muscles) seated in the reach scene (`patient_model="myo"`,
`rehabbot.sim.myo_patient`, `rehabbot.sim.myo_arm`), passive (zero excitation), measured
beside the rigid patient of the same ids. The passive torque is the muscles' generalised force
on the knee or elbow (the coupled joints' share included), gravity on but not counted; the
rest of the limb at its home pose. The static
cuff force is what the strap carries when the robot holds the leg still at a knee angle, from
the scene's home balance at that pose. Throughput is measured with the robot holding its
home setpoints (physics) and with zero actions (env steps), best of three, in this run."""

KNEE_ANGLES_DEG = tuple(range(0, 121, 15))
ELBOW_ANGLES_DEG = (0, 15, 30, 45, 60, 75, 90, 105, 120, 130)
HOLD_ANGLES_DEG = (90, 75, 60, 45, 35, 30, 25, 20)


def static_cuff_force_n(patient_model: str, level: int, knee_deg: float) -> float:
    scene = build_scene("knee", weight_level=level, patient_model=patient_model)
    scene.set_home_pose({"knee_flexion_r": knee_deg})
    data = mujoco.MjData(scene.model)
    data.qpos[:] = scene.home_qpos
    mujoco.mj_forward(scene.model, data)
    return float(np.linalg.norm(statics.cuff_load_force(scene, data)))


def expert_rows(seed: int) -> list[dict]:
    rows = []
    for myo_id, rigid_id in MYO_VARIANTS.items():
        for env_id in (rigid_id, myo_id):
            env = gym.make(env_id)
            expert = ScriptedExpert(env)
            for exercise in range(len(env.unwrapped.config.exercise_table)):
                for level in (0, 4):
                    obs, info = env.reset(seed=seed, options={"exercise": exercise,
                                                              "weight_level": level})
                    steps, peak = 0, 0.0
                    while True:
                        obs, _reward, terminated, truncated, info = env.step(expert(obs))
                        steps += 1
                        peak = max(peak, info["interaction_force_n"])
                        if terminated or truncated:
                            break
                    rows.append({
                        "id": env_id, "exercise": exercise, "weight_level": level,
                        "name": env.unwrapped.config.exercise_table[exercise].name,
                        "seed": seed, "success": bool(info["is_success"]), "steps": steps,
                        "safety_violation": info["safety_violation"], "peak_force_n": peak,
                        "peak_muscle_force_n": info.get("peak_muscle_force_n"),
                        "muscle_work_j": info.get("muscle_work_j"),
                        "robot_work_j": info["robot_work_j"]})
            env.close()
    return rows


def _best_rate(step, count: int, repeats: int = 3) -> float:
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(count):
            step()
        best = min(best, time.perf_counter() - start)
    return count / best


def throughput_rows(steps: int) -> list[dict]:
    rows = []
    for myo_id, rigid_id in MYO_VARIANTS.items():
        for env_id in (rigid_id, myo_id):
            env = gym.make(env_id)
            env.reset(seed=0)
            base = env.unwrapped
            action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

            def env_step(env=env, action=action):
                _obs, _r, terminated, truncated, _info = env.step(action)
                if terminated or truncated:
                    env.reset()

            model, data = base.scene.model, mujoco.MjData(base.scene.model)
            base.scene.reset_data(data)
            rows.append({"id": env_id, "physics_steps_per_s": _best_rate(
                lambda model=model, data=data: mujoco.mj_step(model, data), steps),
                "env_steps_per_s": _best_rate(env_step, max(1, steps // 10))})
            env.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_seed_argument(parser)
    parser.add_argument("--steps", type=int, default=2000,
                        help="physics steps per throughput repeat (env steps: a tenth)")
    add_page_argument(parser, "docs/results/myo-patient")
    args = parser.parse_args(argv)
    if args.steps < 10:
        parser.error(f"--steps must be >= 10, got {args.steps}")
    command = script_command(__file__, argv)
    announce(command)
    scene = build_scene("knee", patient_model="myo")
    curves = {f"hip_{hip}": [muscle_torque_nm(scene, "knee_flexion_r", {
        "hip_flexion_r": hip, "knee_flexion_r": a}) for a in KNEE_ANGLES_DEG] for hip in (90, 0)}
    torque_table = make_table(
        "passive-torque", "MyoLeg's passive knee torque [N m] (positive: towards flexion, "
        "resisting extension), zero excitation",
        ["knee flexion [deg]", "hip flexed 90 deg (seated)", "hip extended (0 deg)"],
        [[a, f"{s:.1f}", f"{e:.1f}"] for a, s, e in zip(KNEE_ANGLES_DEG, curves["hip_90"],
                                                          curves["hip_0"], strict=True)])
    arm = build_scene("upper_right", patient_model="myo")
    elbow = [muscle_torque_nm(arm, "elbow_flexion_r", {"elbow_flexion_r": a})
             for a in ELBOW_ANGLES_DEG]
    elbow_table = make_table(
        "passive-elbow-torque", "MyoArm's passive elbow torque [N m] (positive: towards "
        "flexion), zero excitation, the shoulder at the reach scene's home",
        ["elbow flexion [deg]", "torque [N m]"],
        [[a, f"{t:.2f}"] for a, t in zip(ELBOW_ANGLES_DEG, elbow, strict=True)])
    holds = {model: {level: [static_cuff_force_n(model, level, a) for a in HOLD_ANGLES_DEG]
                     for level in (0, 4)} for model in ("rigid", "myo")}
    hold_table = make_table(
        "static-cuff-force", "Cuff force [N] holding the seated knee still (hip 90 deg); the "
        "lower leg's ISO/TS 15066 limit is 130 N",
        ["knee flexion [deg]", "rigid, level 0", "rigid, level 4", "myo, level 0",
         "myo, level 4"],
        [[a, *(f"{holds[m][lv][i]:.0f}" for m in ("rigid", "myo") for lv in (0, 4))]
         for i, a in enumerate(HOLD_ANGLES_DEG)])
    rows = expert_rows(args.seed)
    expert_table = make_table(
        "expert", "The scripted expert, weight levels 0 and 4 (one episode each)",
        ["id", "exercise", "level", "success", "steps", "peak cuff force [N]",
         "peak muscle force [N]", "muscle work [J]", "robot work [J]"],
        [[r["id"].split("/")[1], f"{r['exercise']} ({r['name']})", r["weight_level"],
          "yes" if r["success"] else f"no ({r['safety_violation']})", r["steps"],
          f"{r['peak_force_n']:.0f}",
          "—" if r["peak_muscle_force_n"] is None else f"{r['peak_muscle_force_n']:.0f}",
          "—" if r["muscle_work_j"] is None else f"{r['muscle_work_j']:.2f}",
          f"{r['robot_work_j']:.2f}"] for r in rows])
    speed = throughput_rows(args.steps)
    rigid_rate = {r["id"]: r for r in speed}
    speed_table = make_table(
        "throughput", "Steps per second in this run (best of 3) and the myo scene's share of "
        "the rigid one's", ["id", "physics steps/s", "env steps/s", "x rigid (physics)",
                            "x rigid (env)"],
        [[r["id"].split("/")[1], f"{r['physics_steps_per_s']:.0f}",
          f"{r['env_steps_per_s']:.0f}",
          *(f"{r[k] / rigid_rate[MYO_VARIANTS.get(r['id'], r['id'])][k]:.2f}"
            for k in ("physics_steps_per_s", "env_steps_per_s"))] for r in speed])
    tables = [torque_table, elbow_table, hold_table, expert_table, speed_table]
    for table in tables:
        print(table_markdown(table), flush=True)
    if args.page is not None:
        write_page(make_document(
            title="The musculoskeletal patient (MyoSuite's legs and arm)", intro=INTRO,
            command=command, generated_by=__file__, tables=tables,
            machine=describe_machine(), seeds={"episodes": args.seed},
            settings={"knee_angles_deg": list(KNEE_ANGLES_DEG),
                      "elbow_angles_deg": list(ELBOW_ANGLES_DEG),
                      "hold_angles_deg": list(HOLD_ANGLES_DEG), "steps": args.steps},
            data={"passive_torque_nm": curves, "passive_elbow_torque_nm": elbow,
                  "static_cuff_force_n": holds,
                  "expert": rows, "throughput": speed}), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
