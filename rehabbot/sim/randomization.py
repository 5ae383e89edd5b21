"""Randomisation for transfer: per episode, draw what a real setup gets wrong about the model.

The rule: an env with ``randomization="transfer"`` (:data:`PRESETS`) draws, at every reset and
from the env's own ``np_random``, every quantity of :class:`RandomizationPreset` below, writes
the drawn model parameters into the ``MjModel`` (always from the values the env was built with,
so nothing accumulates over episodes), re-balances the home state for them, and keeps the draw
(:class:`RandomizationDraw`: ``info["randomization"]`` at reset,
``env.unwrapped.randomization_draw``).
``randomization=None`` (every id but the ``-randomized-`` variants) draws nothing and changes
nothing. What the preset cannot draw in place, the patient's segment lengths (they need a new
scene), comes from the variant's population: each episode seats a body of a cohort drawn across
the adult envelope (:mod:`rehabbot.sim.envelope`).

The ranges, and why (``docs/deployment/randomisation.md`` has the table):

* **segment masses** x U(0.85, 1.15), each segment of the exercised limb independently, its
  inertia with it (on top of the weight level). The patient's segment masses are fractions
  of body mass from one table (de Leva 1996, :mod:`rehabbot.sim.patient`); another table gives
  7 % more for the same shank (Dempster's 4.65 % of body mass against de Leva's 4.33 %), the
  thigh's tables differ by more (10.0 against 14.16 %, mostly where they cut the segment), and
  an individual differs from any table.
* **passive stiffness and damping** of the exercised joints x U(0.5, 2.0), independently: a
  relaxed joint's passive stiffness varies between people by several times; a factor of two
  each way stays well inside the ``stiffness_scale`` the conditions already model (x3).
* **cuff compliance**: the cuff's equality constraint ``solref`` time constant U(0.007,
  0.03) s (nominal 0.01 s; a strap over soft tissue is softer than a rigid coupling, and MuJoCo
  needs at least two physics steps, 0.004 s), its damping ratio U(0.7, 1.3) (nominal 1), and
  ``solimp``'s impedance at zero violation U(0.8, 0.95) (nominal 0.9; ``solimp[1]`` stays 0.95).
* **joint friction** (``frictionloss``): the exercised patient joints U(0, 0.3) N·m (clothes on
  the seat or the bed, a tight cuff: under a third of the patient's 1 N·m effort); each robot
  joint U(0, 2 %) of its torque limit (a harmonic drive's Coulomb friction, which the model
  leaves out and a real controller only partly compensates).
* **sensor noise** on what the agent sees (never on the reward or the safety rules): Gaussian,
  fresh every decision, on the robot's joint angles (0.001 rad: encoder offset after homing,
  far above its resolution), joint velocities (0.01 rad/s: a differentiated encoder) and the
  patient's joint angles (0.01 rad: an estimate from the robot's pose and the limb's lengths).
* **action latency**: 0, 1 or 2 decisions (0-40 ms at 50 Hz: a real robot's command path,
  e.g. a UR's RTDE at 500 Hz plus the policy's own compute), uniform. An action reaches the
  robot exactly that many decisions after the agent sent it (:class:`ActionDelay`); until the
  first one arrives the robot holds its setpoint, as a real servo does.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.sim.scene import Scene, balance_home, weight_factors


@dataclass(frozen=True)
class RandomizationPreset:
    """The ranges of one preset (module docstring: why each); every range is ``(low, high)``
    of a uniform draw, every noise a standard deviation."""

    name: str
    segment_mass_scale: tuple[float, float] = (0.85, 1.15)
    passive_stiffness_scale: tuple[float, float] = (0.5, 2.0)
    passive_damping_scale: tuple[float, float] = (0.5, 2.0)
    cuff_timeconst_s: tuple[float, float] = (0.007, 0.03)
    cuff_dampratio: tuple[float, float] = (0.7, 1.3)
    cuff_impedance_min: tuple[float, float] = (0.8, 0.95)
    patient_frictionloss_nm: tuple[float, float] = (0.0, 0.3)
    robot_frictionloss_fraction: tuple[float, float] = (0.0, 0.02)
    encoder_noise_rad: float = 0.001
    velocity_noise_rad_s: float = 0.01
    patient_angle_noise_rad: float = 0.01
    latency_steps: tuple[int, int] = (0, 2)

    def to_dict(self) -> dict[str, Any]:
        """The preset as plain data (JSON-able)."""
        return dataclasses.asdict(self)


PRESETS: dict[str, RandomizationPreset] = {"transfer": RandomizationPreset("transfer")}


def check_preset(name: Any) -> RandomizationPreset | None:
    """The preset named ``name`` (None for None: no randomisation).

    Raises:
        UsageError: ``name`` is not one of :data:`PRESETS` (the message names it and lists
            them).
    """
    if name is None:
        return None
    if not isinstance(name, str) or name not in PRESETS:
        raise UsageError(f"randomization={name!r} is not one of {list(PRESETS)} or None")
    return PRESETS[name]


@dataclass(frozen=True)
class RandomizationDraw:
    """What one episode drew (module docstring). Per segment, joint or robot joint, in the
    scene's order: ``segment_mass_scale`` (the exercised limb's bodies), the compliant joints'
    ``stiffness_scale``, ``damping_scale`` and ``patient_frictionloss_nm``, per cuff its
    ``cuff_solref`` (time constant [s], damping ratio) and ``cuff_impedance_min``, per robot
    joint ``robot_frictionloss_nm``, and the action latency in decisions."""

    segment_mass_scale: tuple[float, ...]
    stiffness_scale: tuple[float, ...]
    damping_scale: tuple[float, ...]
    cuff_solref: tuple[tuple[float, float], ...]
    cuff_impedance_min: tuple[float, ...]
    patient_frictionloss_nm: tuple[float, ...]
    robot_frictionloss_nm: tuple[float, ...]
    latency_steps: int

    def to_dict(self) -> dict[str, Any]:
        """The draw as plain data (JSON-able)."""
        return dataclasses.asdict(self)


class ActionDelay:
    """A first-in first-out buffer that hands back each action exactly ``steps`` pushes
    later; ``None`` while nothing has arrived yet (the robot holds its setpoint)."""

    def __init__(self, steps: int) -> None:
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
            raise UsageError(f"latency steps={steps!r} must be a non-negative integer")
        self.steps = steps
        self._queue: deque[np.ndarray] = deque()

    def push(self, action: np.ndarray) -> np.ndarray | None:
        """Queue a copy of ``action``; return the action sent ``steps`` pushes ago, or None."""
        self._queue.append(np.array(action, copy=True))
        if len(self._queue) > self.steps:
            return self._queue.popleft()
        return None


class Randomizer:
    """Draws a preset's quantities for one scene and writes them into its model (module
    docstring). Built once per env; :meth:`apply` at every reset, after the weight level is
    set and before the scene's home state is loaded into ``data``."""

    def __init__(self, scene: Scene, preset: RandomizationPreset,
                 robot_torque_limits_nm: np.ndarray) -> None:
        self.scene, self.preset = scene, preset
        model = scene.model
        self.compliant_dofs = np.asarray(scene.compliant_dof_adr, dtype=int)
        self.compliant_joints = np.asarray(model.dof_jntid[self.compliant_dofs], dtype=int)
        self.robot_dofs = np.concatenate([np.asarray(h.dof_adr, dtype=int)
                                          for h in scene.robots])
        self.cuffs = np.array([h.equality_id for h in scene.robots], dtype=int)
        self.robot_torque_limits_nm = np.tile(np.asarray(robot_torque_limits_nm, float),
                                              len(scene.robots))
        # The values the env was built with (its condition included): every draw starts here.
        self.nominal_stiffness = model.jnt_stiffness[self.compliant_joints].copy()
        self.nominal_damping = model.dof_damping[self.compliant_dofs].copy()
        self.nominal_frictionloss = model.dof_frictionloss.copy()
        self.nominal_solref = model.eq_solref[self.cuffs].copy()
        self.nominal_solimp = model.eq_solimp[self.cuffs].copy()
        self.delay = ActionDelay(0)

    def apply(self, rng: np.random.Generator) -> RandomizationDraw:
        """Draw one episode's quantities from ``rng``, write them into the model, re-balance
        the home state and start the action delay; return the draw."""
        preset, scene, model = self.preset, self.scene, self.scene.model
        bodies = scene.limb_body_ids
        n_cuffs, n_compliant = len(self.cuffs), len(self.compliant_dofs)
        mass = rng.uniform(*preset.segment_mass_scale, size=len(bodies))
        stiffness = rng.uniform(*preset.passive_stiffness_scale, size=n_compliant)
        damping = rng.uniform(*preset.passive_damping_scale, size=n_compliant)
        timeconst = rng.uniform(*preset.cuff_timeconst_s, size=n_cuffs)
        dampratio = rng.uniform(*preset.cuff_dampratio, size=n_cuffs)
        impedance = rng.uniform(*preset.cuff_impedance_min, size=n_cuffs)
        patient_friction = rng.uniform(*preset.patient_frictionloss_nm, size=n_compliant)
        robot_friction = rng.uniform(*preset.robot_frictionloss_fraction,
                                     size=len(self.robot_dofs)) * self.robot_torque_limits_nm
        low, high = preset.latency_steps
        latency = int(rng.integers(low, high + 1))

        factor = weight_factors(scene.preset)[scene.weight_level]
        model.body_mass[bodies] = scene.nominal_body_mass[bodies] * factor * mass
        model.body_inertia[bodies] = scene.nominal_body_inertia[bodies] * factor * mass[:, None]
        model.jnt_stiffness[self.compliant_joints] = self.nominal_stiffness * stiffness
        model.dof_damping[self.compliant_dofs] = self.nominal_damping * damping
        model.dof_frictionloss[:] = self.nominal_frictionloss
        model.dof_frictionloss[self.compliant_dofs] += patient_friction
        model.dof_frictionloss[self.robot_dofs] += robot_friction
        model.eq_solref[self.cuffs, 0] = timeconst
        model.eq_solref[self.cuffs, 1] = dampratio
        model.eq_solimp[self.cuffs] = self.nominal_solimp
        model.eq_solimp[self.cuffs, 0] = impedance
        scratch = scene._scratch_data()
        scratch.qpos[:] = model.qpos0
        mujoco.mj_setConst(model, scratch)
        scene.home_setpoints = balance_home(scene)
        self.delay = ActionDelay(latency)
        return RandomizationDraw(
            segment_mass_scale=tuple(mass.tolist()), stiffness_scale=tuple(stiffness.tolist()),
            damping_scale=tuple(damping.tolist()),
            cuff_solref=tuple(zip(timeconst.tolist(), dampratio.tolist(), strict=True)),
            cuff_impedance_min=tuple(impedance.tolist()),
            patient_frictionloss_nm=tuple(patient_friction.tolist()),
            robot_frictionloss_nm=tuple(robot_friction.tolist()), latency_steps=latency)

    def noise(self, rng: np.random.Generator, n_theta: int, n_velocity: int,
              n_phi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One decision's sensor noise: on the robot joint angles, joint velocities and the
        patient's joint angles."""
        preset = self.preset
        return (rng.normal(0.0, preset.encoder_noise_rad, n_theta),
                rng.normal(0.0, preset.velocity_noise_rad_s, n_velocity),
                rng.normal(0.0, preset.patient_angle_noise_rad, n_phi))
