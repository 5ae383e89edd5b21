"""The simulator backend: RehabBot's own scene behind the robot interface of
:mod:`rehabbot.deploy.backend`.

A :class:`SimulatorBackend` holds one env (any one-robot id, any kwargs: a patient condition,
a body, the FR3). :meth:`SimulatorBackend.command` makes the joint targets the servo setpoints
(clipped to the env's setpoint box, as the env's controller clips) and runs one env step with
an action that holds them, so the patient, the safety rules, the target switching and the
reward all run as in ``env.step``. :meth:`SimulatorBackend.policy_target` is the setpoint a
policy's action would command (the env's own law,
:meth:`rehabbot.envs.core.RehabEnvCore.setpoints_for`): a closed loop
``policy -> policy_target -> command`` therefore reproduces ``env.step(action)`` bit for bit,
while a filter between the two may change the command.

One difference remains with a reward that charges the change of action (a ``smoothness``
weight): a commanded step's own action is the hold action, so that term reads it.

Control modes: ``joint_delta`` (every ``-v0``/``-v1``/``-v2`` id) and ``joint_velocity``,
whose zero action holds the setpoints exactly. ``joint_position`` and ``torque`` are refused
by name, and so is a two-robot env (a bilateral id).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import RobotState
from rehabbot.envs.registration import NAMESPACE

HOLDING_MODES = ("joint_delta", "joint_velocity")


class SimulatorBackend:
    """One simulated robot and patient (module docstring)."""

    def __init__(self, env_id: str, **env_kwargs: Any) -> None:
        full_id = env_id if "/" in env_id else f"{NAMESPACE}/{env_id}"
        try:
            env = gym.make(full_id, **env_kwargs)
        except gym.error.Error as err:
            raise UsageError(f"simulator backend: cannot make {env_id!r}: {err}") from None
        self._adopt(env)

    @classmethod
    def from_env(cls, env: gym.Env) -> SimulatorBackend:
        """A backend on an env already made (its wrappers are kept for :meth:`reset`)."""
        backend = cls.__new__(cls)
        backend._adopt(env)
        return backend

    def _adopt(self, env: gym.Env) -> None:
        core = env.unwrapped
        if len(getattr(core, "handles", ())) != 1:
            raise UsageError(f"simulator backend: {env.spec.id if env.spec else env!r} has "
                             "two robots; a backend drives one robot")
        mode = core.config.control_mode
        if mode not in HOLDING_MODES:
            raise UsageError(f"simulator backend: control_mode={mode!r} cannot be commanded "
                             f"joint targets; use one of {list(HOLDING_MODES)}")
        unit = core.unit_actions
        native_zero = np.zeros(core.controller.action_space.shape)
        if unit is not None and not np.array_equal(unit.center, native_zero):
            raise UsageError("simulator backend: the env's unit actions are not centred on "
                             "zero, so no unit action holds the setpoints")
        self.wrapped = env
        self.env = core
        handle = core.handle
        self.joint_names = tuple(handle.robot.joint_names)
        self.control_dt_s = float(core.dt)
        self._hold = np.zeros(core.action_space.shape, dtype=np.float32)
        self._qpos_adr = np.asarray(handle.qpos_adr)
        self._dof_adr = np.asarray(handle.dof_adr)
        scene = core.scene
        self._patient_qpos_adr = np.asarray(scene.exercised_qpos_adr)
        self._patient_dof_adr = np.asarray(scene.exercised_dof_adr)
        self._cuff_row = core.safety.cuff_rows[0]
        self._stopped = False
        self.last_step: tuple[np.ndarray, float, bool, bool, dict] | None = None

    # ------------------------------------------------------------------------------------------
    def reset(self, seed: int | None = None,
              options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode (the env's ``reset``); a stopped backend runs again."""
        self._stopped = False
        self.last_step = None
        return self.wrapped.reset(seed=seed, options=options)

    def state(self) -> RobotState:
        data = self.env.data
        return RobotState(
            time_s=float(data.time),
            q_rad=data.qpos[self._qpos_adr].copy(),
            dq_rad_s=data.qvel[self._dof_adr].copy(),
            cuff_force_n=float(self.env.safety.cuff_force_n(data)),
            patient_q_rad=data.qpos[self._patient_qpos_adr].copy(),
            patient_dq_rad_s=data.qvel[self._patient_dof_adr].copy())

    def policy_target(self, action: Any) -> np.ndarray:
        """The joint targets [rad] ``env.step(action)`` would command (a new array)."""
        try:
            return self.env.setpoints_for(action)
        except ValueError as err:
            raise UsageError(f"simulator backend: {err}") from None

    def command(self, q_target_rad: Any) -> None:
        """One decision toward ``q_target_rad``: the setpoints become the targets (clipped to
        the env's setpoint box), then one env step holds them (its result: :attr:`last_step`).
        Refused once stopped, or once the episode ended (call :meth:`reset`)."""
        if self._stopped:
            raise UsageError("simulator backend: stopped; reset() before commanding again")
        target = np.asarray(q_target_rad, dtype=float)
        if target.shape != (len(self.joint_names),):
            raise UsageError(f"simulator backend: a command needs {len(self.joint_names)} "
                             f"joint positions, got shape {target.shape}")
        if not np.all(np.isfinite(target)):
            raise UsageError(f"simulator backend: non-finite joint target {target.tolist()}")
        self.env.controller.command_setpoint(target)
        self.last_step = self.wrapped.step(self._hold)

    def stop(self) -> None:
        """Hold where the robot is: the setpoints become the measured joint positions, and
        every later command is refused until :meth:`reset`."""
        data = self.env.data
        self.env.controller.command_setpoint(data.qpos[self._qpos_adr])
        self._stopped = True

    def healthy(self) -> bool:
        return not self._stopped

    # ------------------------------------------------------------------------------------------
    def cuff_force_vector_n(self) -> np.ndarray:
        """The cuff's constraint force [N], world frame, as it acts on the robot (the
        equality's three rows; zero when the cuff is not active), a new array: the limb feels
        its opposite. It is the force of the last physics step, one step older than the
        state's joint angles."""
        data = self.env.data
        row = self._cuff_row
        if data.efc_force.shape[0] < row + 3 or data.ne < row + 3:
            return np.zeros(3)
        return data.efc_force[row:row + 3].copy()

    def rom_bounds_rad(self) -> tuple[np.ndarray, np.ndarray]:
        """The exercised patient joints' anatomical range (low, high) [rad], without the
        range-of-motion rule's tolerance."""
        model = self.env.model
        joints = model.dof_jntid[self._patient_dof_adr]
        return model.jnt_range[joints, 0].copy(), model.jnt_range[joints, 1].copy()

    def rom_tolerance_rad(self) -> float:
        """How far beyond the range the env's range-of-motion rule lets a joint go [rad]."""
        return float(np.deg2rad(self.env.config.rom_tolerance_deg))

    def cuff_force_limit_n(self) -> float:
        """The cuff's ISO/TS 15066 force limit [N] (or the env's ``cuff_force_limit_n``)."""
        return float(self.env.safety.force_limit_n)

    def setpoint_bounds_rad(self) -> tuple[np.ndarray, np.ndarray]:
        """The box the env clips setpoints to (low, high) [rad] (copies)."""
        return (np.array(self.env.setpoint_low_rad, dtype=float),
                np.array(self.env.setpoint_high_rad, dtype=float))

    def close(self) -> None:
        self.wrapped.close()
