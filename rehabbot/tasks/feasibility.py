"""Whether a patient profile can do the exercises of a scene at all, checked once when an env
is built so that an unsupported combination fails loudly instead of ending every episode at
its first step.

A combination is refused (``ValueError`` naming the profile, the weight level and the value)
when

* a target of an exercise lies outside the setpoint bounds or the observation bounds (the
  coupled kinematics of a very short patient can ask for robot angles beyond the paper's
  Table 3 ranges), or
* the home state at a weight level the env can use already breaks a safety rule: the cuff
  carries more than its ISO/TS 15066 limit at rest (a heavy leg held up by the strap), or the
  robot already touches the patient or the furniture; or
* a robot joint needs its whole torque limit to hold the limb at rest (the FR3, 87 N·m on its
  shoulder, holding a tall patient's heavy leg up on the bed), so the limb sags and nothing is
  left to move it.

The README's "Failure modes" section lists the profiles known to be refused.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import mujoco
import numpy as np

from rehabbot.sim.physics import SafetyMonitor
from rehabbot.sim.scene import Scene
from rehabbot.tasks.targets import TargetSequence

TARGET_BOUND_TOLERANCE_RAD = 1e-9
SETTLE_STEPS = 100  # physics steps of holding still (0.2 s at the default 2 ms)
# A joint whose actuator torque is this share of its limit at rest is saturated (the limit
# clamps the total, so a saturated joint reads its limit exactly).
SATURATED_SHARE = 0.999


def check_targets(targets: Sequence[TargetSequence], low_rad: np.ndarray,
                  high_rad: np.ndarray, position_bound_m: float, profile) -> None:
    """Raise ``ValueError`` if a target lies outside the setpoint or position bounds."""
    for sequence in targets:
        robot = sequence.robot_rad
        below = robot < low_rad - TARGET_BOUND_TOLERANCE_RAD
        above = robot > high_rad + TARGET_BOUND_TOLERANCE_RAD
        if below.any() or above.any():
            i, j = np.argwhere(below | above)[0]
            raise ValueError(
                f"profile {profile}: target {i} of exercise {sequence.exercise.name!r} needs "
                f"robot joint {j} at {robot[i, j]:.3f} rad, outside its setpoint bounds "
                f"[{low_rad[j]:.3f}, {high_rad[j]:.3f}] rad; this scene does not support the "
                "profile (README, Failure modes)")
        if np.abs(sequence.tool_pos_base_m).max() > position_bound_m:
            raise ValueError(f"profile {profile}: a target of exercise "
                             f"{sequence.exercise.name!r} lies beyond {position_bound_m} m of "
                             "the robot base")


def home_violation(scene: Scene, data: mujoco.MjData, safety: SafetyMonitor,
                   level: int) -> tuple[str, float] | None:
    """The safety rule (and the cuff force [N]) that the home state at ``level`` breaks while
    the robot's servos hold it for ``SETTLE_STEPS`` physics steps, or None. The load shared
    between the cuff and the furniture settles within the first steps (the cuff's share can
    rise by about 10 % from the reset's solution), so the rules are checked on every step.
    ``data`` is left at the settled state."""
    if level != scene.weight_level:
        scene.set_weight_level(level)
    model = scene.model
    disabled = model.opt.disableactuator
    model.opt.disableactuator = 0  # the servos hold the home setpoints, whatever the mode
    try:
        scene.reset_data(data)
        safety.reset(data)
        for _ in range(SETTLE_STEPS):
            force_n = safety.cuff_force_n(data)
            rule = safety.check(data, force_n)
            if rule is not None:
                return rule, force_n
            mujoco.mj_step(model, data)
        return None
    finally:
        model.opt.disableactuator = disabled


def saturated_joint(scene: Scene, data: mujoco.MjData) -> tuple[str, float] | None:
    """``(joint name, torque limit [N·m])`` of a robot joint working at its torque limit in
    ``data`` (the first found), or None."""
    for handle in scene.robots:
        limits = handle.robot.torque_limits()
        share = np.abs(data.qfrc_actuator[handle.dof_adr]) / limits
        j = int(share.argmax())
        if share[j] >= SATURATED_SHARE:
            return f"{handle.prefix}{handle.robot.joint_names[j]}", float(limits[j])
    return None


def unusable_levels(scene: Scene, data: mujoco.MjData, safety: SafetyMonitor,
                    levels: Iterable[int], profile) -> dict[int, str]:
    """Weight levels whose home state breaks a safety rule or saturates a robot joint, each
    with the error message to raise when it is asked for. Leaves the scene at the last level
    checked."""
    messages = {}
    for level in levels:
        found = home_violation(scene, data, safety, level)
        if found is None:
            saturated = saturated_joint(scene, data)
            if saturated is not None:
                joint, limit = saturated
                messages[level] = (
                    f"profile {profile} at weight_level {level}: robot joint {joint} needs its "
                    f"whole {limit:.0f} N·m torque limit to hold the limb at rest, with "
                    f"robot={scene.options.robot!r}; this scene does not support the profile "
                    "(README, Failure modes)")
            continue
        rule, force_n = found
        if rule == "cuff_force":
            limit = (f"cuff_force_limit_n={safety.thresholds.cuff_force_limit_n} N"
                     if safety.thresholds.cuff_force_limit_n is not None else
                     f"the {safety.force_limit_n:.0f} N ISO/TS 15066 limit of the strapped "
                     "region; pass cuff_force_limit_n= to accept it")
            messages[level] = (
                f"profile {profile} at weight_level {level}: the cuff carries {force_n:.0f} N "
                f"with the limb at rest, above {limit}")
        else:
            messages[level] = (
                f"profile {profile} at weight_level {level}: the home state already breaks "
                f"the {rule!r} rule ({_describe(scene, data, rule)}); this scene does not "
                "support the profile (README, Failure modes)")
    return messages


def refuse(messages: dict[int, str], levels: Sequence[int], level: int) -> None:
    """Raise the message of ``level`` with a hint at the usable levels of ``levels``."""
    usable = [lv for lv in levels if lv not in messages]
    hint = f"; weight levels {usable} are usable (pass weight_level=)" if usable else ""
    raise ValueError(messages[level] + hint)


def _describe(scene: Scene, data: mujoco.MjData, rule: str) -> str:
    model = scene.model
    if rule == "unintended_contact":
        robot = set(scene.robot_geom_ids.tolist())
        for c in data.contact[: data.ncon]:
            a, b = (int(g) for g in c.geom)
            if (a in robot) != (b in robot):
                names = [model.geom(g).name or f"geom {g}" for g in (a, b)]
                return f"{names[0]} touches {names[1]}, {-c.dist * 1000:.1f} mm deep"
    return "at rest"
