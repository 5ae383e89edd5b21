"""``RehabEnv``: a UR5e strapped to a patient's hand or leg moves the limb through a therapy
exercise (Gymnasium API). Every registered one-robot, one-limb id (the paper's four ``-v0`` ids,
their ``-v1`` and ``-v2``, the condition variants) is this class with different keyword
arguments (:mod:`rehabbot.envs.registration`); ``PopulationEnv`` holds one per patient.

## Description
A seated (arm, knee) or supine (hip) patient, sized from a :class:`~rehabbot.sim.patient.PatientProfile`, has one
hand or shank strapped to the cuff of a UR5e. The agent moves the robot's joints; the
patient's relaxed limb follows the cuff. Each episode runs one exercise of the limb's table
(:data:`rehabbot.tasks.exercises.EXERCISES`, or the ``exercises`` kwarg), defined in the
patient's joint space; the robot's targets are the joint angles that hold the limb at each key
pose (reaching) or along a minimum-jerk path (trajectory following). The agent must reach the
targets in order, within ``target_tolerance_rad`` on every joint, without hurting the patient.

## Action space
``control_mode="joint_delta"`` (the paper's ids): ``Box(-pi/400, pi/400, (6,), float32)``.

| index | robot joint | unit |
|---|---|---|
| 0 | shoulder_pan | rad added to the joint's impedance setpoint |
| 1 | shoulder_lift | rad |
| 2 | elbow | rad |
| 3 | wrist_1 | rad |
| 4 | wrist_2 | rad |
| 5 | wrist_3 | rad |

A setpoint drives a gravity-compensated joint impedance controller whose torque is saturated
at the UR5e limits (150 / 28 N·m). With ``robot="fr3"`` the action has 7 values, one per joint
``fr3_joint1`` .. ``fr3_joint7`` (limits 87 / 12 N·m), and theta*, theta are 7 wide (25
observations; :mod:`rehabbot.sim.robots`). Setpoints are kept inside the setpoint bounds (the paper's
Table 3 ranges in robot joint space). Other modes (:mod:`rehabbot.envs.control`):
``"joint_position"`` (``Box(-r - 0.5, r + 0.5)`` with ``r`` the joints' hardware ranges, rad;
actions outside this patient's setpoint bounds are clipped to them), ``"joint_velocity"``
(``Box(-max_speed_rad_s, max_speed_rad_s)``, rad/s), ``"torque"`` (``Box(-1, 1)``, fraction
of each joint's torque limit, added to gravity compensation, servos off). Finite actions
outside the box are clipped (counted in ``info["action_clipped"]``); NaN/inf (the error names
the indices), a wrong shape, or a dtype that is not a real number (bool, complex, str, object)
raise ``ValueError``. float64, integer and list actions are accepted.

## Observation space
``Box(low, high, (23,), float32)`` in the paper's order (:mod:`rehabbot.tasks.observation`).
Positions are in the robot base frame (origin on the base's mounting face, z up the base
axis, x along the zero of shoulder_pan). The bounds are the same for every patient profile and
weight level of an id (``r``: each robot joint's hardware range, 2 pi or pi for the elbow).

| index | observation | unit | bounds |
|---|---|---|---|
| 0-5 | theta*: target robot joint angles (pan, lift, elbow, wrist 1-3) | rad | +-(r + 0.5) |
| 6-8 | p*: target tool (flange) position x, y, z, base frame | m | +-1.35 |
| 9-14 | theta: robot joint angles | rad | +-(r + 1.1) |
| 15-17 | p: tool (flange) position, base frame | m | +-1.35 |
| 18-20 | phi: the patient's exercised joints (shoulder flexion, shoulder abduction, elbow flexion; or hip flexion, hip abduction, knee flexion), flexion positive | rad | anatomical range +- 0.5 |
| 21 | e: exercise (0, 1, ...) | - | [0, number of exercises - 1] |
| 22 | l: weight level (0..4) | - | [0, 4] |

### The -v2 ids: ``observation="agent"``, ``action_scale="unit"``
The ``-v2`` ids are the ``-v1`` task and reward with an interface any learner can use: the
action is ``Box(-1, 1, (n,), float32)``, mapped linearly onto the control mode's box
(``joint_delta``: -1 .. +1 is -pi/400 .. +pi/400 rad; ``joint_position``: the patient's
setpoint bounds; :class:`rehabbot.envs.control.UnitActions`), and the observation is
``Box(-2, 2, (50,), float32)`` (56 with the FR3), every entry scaled to [-1, 1] except
three that pass 1 near a bound or at a stop: ``theta_in_bounds`` and ``phi_in_range``
(clipped at +-2) and ``cuff_force`` (clipped to [0, 2]; docs/envs.md, "Which observation
values pass 1"). The formulas are in :mod:`rehabbot.tasks.agent_observation`:

| index | observation | scale |
|---|---|---|
| 0-5 | ``joint_error_fine``: theta* - theta, the active target's joint errors | tanh(./0.05 rad) |
| 6-11 | ``joint_error``: the same, coarse | tanh(./0.5 rad) |
| 12-14 | ``tool_error_fine``: p* - p, base frame | tanh(./0.05 m) |
| 15-17 | ``tool_error``: the same, coarse | tanh(./0.2 m) |
| 18-23 | ``next_target``: theta*_{i+1} - theta*_i (0 at the last target) | tanh(./0.5 rad) |
| 24-29 | ``setpoint_lead``: servo setpoint - theta (0 in torque mode) | tanh(./0.05 rad) |
| 30-35 | ``joint_velocity``: the robot joints' velocities | tanh(./0.5 rad/s) |
| 36-41 | ``theta_in_bounds``: theta, -1 / +1 at the setpoint bounds | clipped to +-2 |
| 42-44 | ``phi_in_range``: the patient's exercised joints, -1 / +1 at the ends of their range | clipped to +-2 |
| 45 | ``cuff_force``: cuff force / its limit (the cuff-force rule fires above 1) | clipped to [0, 2] |
| 46-47 | ``exercise``: one-hot | 0 or 1 |
| 48 | ``weight_level``: l / 2 - 1 | [-1, 1] |
| 49 | ``target_progress``: 2 i / (N - 1) - 1 for the active target i of N | [-1, 1] |

The paper's 23 fields stay available: ``info["paper_observation"]`` (every step) and
``env.unwrapped.paper_observation()``, in the layout above (``env.unwrapped.layout``;
``env.unwrapped.agent_layout`` names the agent observation's fields).

## Rewards
Named terms, each reported as ``info["reward_<name>"]``; the reward is their sum
(``docs/envs.md``, Reward). ``reward="paper"`` (the -v0 ids): eq. (5),
:mod:`rehabbot.tasks.reward`: ``reward_distance = -||theta - theta*_i||_2``, ``reward_bonus``
(``intermediate_bonus`` / ``final_bonus`` when ``||theta - theta*_i||_inf <
target_tolerance_rad``), optional ``reward_smoothness`` and ``reward_effort``, ``reward_safety``
on a stop (a stop never pays); stalling can be worth more than reaching a target
(``benchmarks/probes/reward_trap.py``). ``reward="progress"`` (the -v1 ids),
:class:`rehabbot.tasks.reward.ProgressReward`: ``reward_progress`` (``progress_weight`` x the decrease
of the joint-space path still to travel), ``reward_bonus``, ``reward_time = -time_cost``, the
optional terms and ``reward_safety``; reaching each target beats stalling for every gamma in
[0.95, 0.999]. ``info["cost"]`` is 1.0 in a step where a safety rule fired, else 0.0
(Safety-Gymnasium's convention).

A profile or condition that cannot do the exercises in its scene (the robot cannot reach the
cuff, a target outside the setpoint bounds, a home state that already breaks a safety rule, a
condition whose steady load exceeds the cuff's force limit) is refused with a ``ValueError``
when the env is built (:mod:`rehabbot.tasks.feasibility`, :mod:`rehabbot.envs.condition_setup`).

## The patient
``condition`` (:class:`rehabbot.sim.conditions.PatientCondition`, ``docs/conditions.md``) adds
spasticity, contracture, weakness, tremor, effort and (on muscles) fatigue; the default is a
healthy, passive limb.
Every id reports ``info["patient_torque_nm"]`` (the patient's muscle torques on the exercised
joints), ``info["patient_work_j"]`` and ``info["robot_work_j"]`` (work on the limb since reset,
counted every physics step) and ``info["assistance_ratio"]`` (the robot's share of the positive
work; 1.0 until the patient does positive work).

``patient_model="myo"`` (the knee and hip ids; ``rehab-knee-myo-v2``, ``rehab-hip-myo-v2``)
seats MyoSuite's musculoskeletal legs (:mod:`rehabbot.sim.myo_patient`, 80 muscles); on the
right-arm ids (``rehab-reach-myo-v2``) MyoSuite's right arm (:mod:`rehabbot.sim.myo_arm`, 63
muscles; the left arm is refused). The muscles are relaxed unless a condition excites them
(every condition acts on them: :mod:`rehabbot.sim.muscle_drive`);
``pip install "rehabbot[myo]"``; the default profile only. Its ``info`` adds the exercised
limb's muscles (:mod:`rehabbot.sim.muscles`):
``muscle_excitation`` and ``muscle_activation`` (means, 0-1), ``muscle_force_n`` (their total
pull), ``peak_muscle_force_n`` (the largest pull of one muscle since reset) and
``muscle_work_j`` (their forces' work on the limb since reset; negative when they absorb the
robot's work); with ``fatigue_scale > 0``, ``muscle_fatigue`` (the most fatigued
muscle's fatigued fraction, 3CC-r).

## Starting state
The home posture of the scene (cuff satisfied, static equilibrium), no noise. The exercise and
the weight level are drawn from ``np_random`` unless fixed by the constructor or by
``reset(options={"exercise": e, "weight_level": l})``.

## Episode end
* terminated, success: the last target is reached (``info["is_success"]``);
* terminated, safety: a rule of :mod:`rehabbot.sim.physics` fires
  (``info["safety_violation"]``): ``"instability"``, ``"range_of_motion"``, ``"cuff_force"``
  or ``"unintended_contact"``;
* truncated: ``max_episode_steps`` (1000 = 20 s), applied by the registration's ``TimeLimit``.

``step()`` before the first ``reset()`` or after a termination raises
``gymnasium.error.ResetNeeded``; after ``close()`` it raises ``RuntimeError``; ``close()`` twice
is a no-op. An ``"instability"`` always ends the episode (even with
``terminate_on_safety=False``) and returns the last healthy observation; the next ``reset()``
starts from the healthy home state.

## Arguments
The flat keywords below are the fields of the groups of a
:class:`rehabbot.envs.config.RehabEnvConfig` (``scene``, ``patient``, ``task``, ``control``,
``safety``, ``reward``, ``render``: the table's second column), validated before anything is
built (``ValueError`` naming the value and its valid choices or range). A group may be passed
whole, as its config class or a dict of its fields (``RehabEnv(reward={"design": "progress",
"time_cost": 0.1})``; ``reward="progress"``, a string, is the design), with flat keywords
applied on top; ``RehabEnv(config)`` takes a whole config instead.

| kwarg | group | default | meaning |
|---|---|---|---|
| ``limb`` | scene | ``"arm"`` | ``"arm"`` (seated, shoulder + elbow), ``"hip"`` (supine), ``"knee"`` (seated) |
| ``side`` | scene | ``"right"`` | ``"right"`` or ``"left"`` arm / leg |
| ``task_type`` | task | ``"reaching"`` | ``"reaching"`` (the key poses) or ``"trajectory"`` (dense min-jerk waypoints) |
| ``control_mode`` | control | ``"joint_delta"`` | see Action space |
| ``profile`` | patient | ``None`` | :class:`~rehabbot.sim.patient.PatientProfile` or a dict of its fields (default 1.75 m, 75 kg, male) |
| ``condition`` | patient | ``None`` | :class:`~rehabbot.sim.conditions.PatientCondition` or a dict of its fields (``spasticity_mas``, ``stiffness_scale``, ``rom_scale``, ``strength_fraction``, ``tremor_hz``, ``tremor_amplitude_nm``, ``effort``, ``effort_fraction``, ``reaction_delay_s``, ``fatigue_scale``); ``None`` = healthy, passive. A condition variant id (``rehab-reach-spastic-v1``, ...) refuses a ``condition=`` that would replace its own: use the base id |
| ``weight_level`` | patient | ``None`` | fix the weight level 0..4 (limb mass x1.0 .. x2.0); ``None`` draws it |
| ``exercise`` | task | ``None`` | fix the exercise (an index into the table); ``None`` draws it |
| ``exercises`` | task | ``None`` | the exercise table: :class:`~rehabbot.tasks.exercises.Exercise` objects or dicts of their fields; ``None`` = the limb's built-in two |
| ``robot`` | scene | ``"ur5e"`` | the robot on the cuff: ``"ur5e"`` (the paper's) or ``"fr3"`` (Franka Research 3, 7 joints) |
| ``cuff`` | scene | ``"connect"`` | ``"connect"`` (strap: position only) or ``"weld"`` |
| ``base_reorientation_deg`` | scene | 0.0 | rotation of the robot base about its vertical axis, in [-180, 180] |
| ``frame_skip`` | control | 10 | physics steps per decision |
| ``timestep_s`` | scene | 0.002 | physics step in [1e-4, 0.005] s; ``dt = frame_skip * timestep_s`` (0.02 s, 50 Hz) |
| ``patient_model`` | scene | ``"rigid"`` | the patient's body: ``"rigid"`` links, or ``"myo"``: MyoSuite's musculoskeletal legs (knee and hip) or right arm (reach, right side) |
| ``randomization`` | scene | None | ``"transfer"``: segment masses, passive stiffness and damping, the cuff's compliance, joint friction, sensor noise and 0-2 decisions of action latency drawn every episode (:mod:`rehabbot.sim.randomization`); None draws nothing |
| ``target_tolerance_rad`` | task | 0.05 | epsilon of eq. (5) |
| ``reward`` | reward | ``"paper"`` | ``"paper"`` (eq. (5), the -v0 ids) or ``"progress"`` (the -v1 ids); see Rewards |
| ``observation`` | task | ``"paper"`` | ``"paper"`` (the paper's 23 fields, -v0 and -v1) or ``"agent"`` (the -v2 ids; see Observation space) |
| ``action_scale`` | control | ``"native"`` | ``"native"`` (actions in the control mode's units, -v0 and -v1) or ``"unit"`` (``Box(-1, 1)``, the -v2 ids) |
| ``progress_weight`` | reward | 10.0 | progress reward: paid per rad of path travelled |
| ``time_cost`` | reward | 0.05 | progress reward: cost of every step |
| ``intermediate_bonus`` | reward | 10.0 | B_i for i < N - 1 |
| ``final_bonus`` | reward | 100.0 | B_{N-1} |
| ``smoothness_weight`` | reward | 0.0 | weight of ``reward_smoothness`` |
| ``effort_weight`` | reward | 0.0 | weight of ``reward_effort`` |
| ``terminate_on_safety`` | safety | True | end the episode (with the penalty) when a safety rule fires; if False the rule is only reported |
| ``safety_penalty`` | reward | ``"hold"`` | ``"hold"`` (every reward: the gap to the best hold of the episode, one step more and a margin of 1.0, so a stop never pays) or, paper reward only, ``"worst_case"`` (steps left x worst per-step loss); :mod:`rehabbot.tasks.reward` |
| ``safety_penalty_steps`` | reward | None | charge at most this many steps at the current hold cost instead (with a cap a stop can pay) |
| ``rom_tolerance_deg`` | safety | 2.0 | range-of-motion rule: allowed excess beyond the anatomical range, in [0, 10] deg (10: the knee hyperextension a CPM device allows, the Artromot K1's -10 deg; ``docs/envs.md``, Safety terminations) |
| ``cuff_force_limit_n`` | safety | None | cuff force rule: limit in N for every cuff, in [1, 880] N (880 = 4 x the largest ISO/TS 15066 quasi-static limit, thighs 220 N); None = the quasi-static limit of the region each cuff holds |
| ``contact_tolerance_m`` | safety | 0.002 | contact rule: penetration that counts as contact, in [0, 0.01] m (2 x the deepest limb compression at an ISO/TS 15066 quasi-static limit, upper arm 150 N / 30 N/mm = 5 mm) |
| ``max_episode_steps`` | task | 1000 | horizon used by the safety penalty, in [1, 10**6] (the registration's TimeLimit uses the same). ``gym.make(id, max_episode_steps=m)`` sets both: the env takes its TimeLimit's ``m`` as its horizon; ``m <= 0`` (Gymnasium's ``-1`` = no time limit included) is refused (:mod:`rehabbot.envs.registration`). A ``RehabEnv`` built directly never truncates: wrap it as ``TimeLimit(RehabEnv(..., max_episode_steps=m), m)`` |
| ``segment_s`` | task | 3.0 | trajectory: duration of each min-jerk segment between key poses |
| ``waypoint_dt_s`` | task | 0.1 | trajectory: sampling period of the min-jerk path |
| ``min_waypoint_spacing_rad`` | task | 0.1 | trajectory: minimum distance (inf-norm, robot joints) between waypoints |
| ``max_speed_rad_s`` | control | 0.5 | ``joint_velocity`` mode: action bound |
| ``render_mode`` | render | None | ``"human"``, ``"rgb_array"`` or ``"depth_array"`` |
| ``width``, ``height`` | render | 640, 480 | image size in pixels |
| ``camera_name`` | render | ``"overview"`` | ``"overview"``, ``"front"``, ``"side"`` or None (free camera) |

``depth_array`` images hold the distance from the camera in metres; pixels that see no geometry
hold the camera's far-plane distance. ``env.dt`` is the seconds per step, as in Gymnasium's
MuJoCo envs.
"""

from __future__ import annotations

from typing import Any, ClassVar

from rehabbot.envs.build import build_parts
from rehabbot.envs.config import RehabEnvConfig, config_from
from rehabbot.envs.core import RehabEnvCore


class RehabEnv(RehabEnvCore):
    """A UR5e moves a patient's limb through a therapy exercise (see the module docstring).
    ``reset`` and ``step`` are the env core's (:mod:`rehabbot.envs.core`)."""

    config_class: ClassVar[type] = RehabEnvConfig

    def __init__(self, config: RehabEnvConfig | None = None, **kwargs: Any) -> None:
        self.config = config = config_from(RehabEnvConfig, "RehabEnv", config, kwargs)
        parts = build_parts(config)  # ValueError for a patient who cannot do the exercises
        self.handle = parts.handles[0]
        self.joint_low_rad, self.joint_high_rad = parts.joint_low_rad, parts.joint_high_rad
        self.compliant_ranges_rad = parts.compliant_ranges_rad  # (reduced by rom_scale)
        self._adopt(parts)
