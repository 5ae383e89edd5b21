"""What ``rehabbot deploy`` does around a session (:mod:`rehabbot.deploy.session`): the policy
and the env it runs in, the twin's and the robot's filter settings, the robot's connection,
and :func:`deploy`, which checks all of them before anything moves.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Any

import numpy as np

from rehabbot.common.errors import UsageError
from rehabbot.deploy.backend import BACKENDS, RobotBackend, RobotState
from rehabbot.deploy.safety_filter import FilterConfig, SafetyFilter
from rehabbot.deploy.session import (
    DeploymentSession,
    SessionResult,
    SessionSettings,
)
from rehabbot.deploy.session_log import (
    SessionLogWriter,
    check_session_folder,
    session_header,
)
from rehabbot.deploy.simulator import SimulatorBackend
from rehabbot.rl.experts import native_action_box
from rehabbot.rl.policies import LoadedPolicy, PolicyError, env_for, load_policy

ONNX_SUFFIX = ".onnx"
#: Margin on the env's own caps, so that the policy's largest step is not clipped by round-off.
CAP_MARGIN = 1e-6
#: The robot filter's acceleration cap at most this share of the robot backend's own: the
#: quintic segment between two targets (rehabbot.deploy.interpolation) peaks at a few times
#: the targets' own acceleration where they change direction, and beyond the backend's cap
#: its servo loop rate-limits the setpoints, which then lag the targets.
ROBOT_ACCEL_SHARE = 0.5


def policy_env(spec: str, env_id: str | None = None,
               env_kwargs: dict | None = None) -> tuple[str, dict]:
    """The env id and kwargs to run ``spec`` in: ``env_id`` if given, else the one the policy
    was trained on (a run's manifest, a zoo agent, an ONNX file's metadata), with
    ``env_kwargs`` on top (:func:`rehabbot.rl.policies.env_for`)."""
    if not str(spec).lower().endswith(ONNX_SUFFIX):
        return env_for([spec], env_id, env_kwargs)
    from rehabbot.envs.registration import resolve_env_id
    from rehabbot.rl.onnx_export import load_onnx_policy

    meta = load_onnx_policy(spec).metadata
    kwargs = {**dict(meta.get("env_kwargs") or {}), **dict(env_kwargs or {})}
    return resolve_env_id(env_id or str(meta["env_id"])), kwargs


def load_session_policy(spec: str, env: Any) -> LoadedPolicy:
    """The policy of ``spec`` for ``env``: what :func:`rehabbot.rl.policies.load_policy`
    loads, or an ONNX file of ``rehabbot export`` (run with onnxruntime).

    Raises:
        PolicyError: the ONNX file's observation or action size is not the env's.
    """
    if not str(spec).lower().endswith(ONNX_SUFFIX):
        return load_policy(spec, env)
    from rehabbot.rl.onnx_export import load_onnx_policy

    onnx = load_onnx_policy(spec)
    sizes = (onnx.observation_size, onnx.action_size)
    wanted = (env.observation_space.shape[0], env.action_space.shape[0])
    if sizes != wanted:
        raise PolicyError(f"ONNX policy {spec!r} takes {sizes[0]} observations and gives "
                          f"{sizes[1]} actions; the env has {wanted[0]} and {wanted[1]}")
    return LoadedPolicy(policy=onnx, label=f"onnx-{onnx.metadata.get('algo') or 'policy'}",
                        kind="onnx", algo=onnx.metadata.get("algo"), model_path=Path(spec),
                        spec=str(spec))


def env_caps(twin: SimulatorBackend) -> tuple[list[float], list[float]]:
    """The fastest a policy of the twin's env can move the setpoints: per joint, the speed
    [rad/s] of its largest step per decision and the acceleration [rad/s^2] of reversing it
    (with :data:`CAP_MARGIN`): the filter's caps when the user gives none."""
    low, high = native_action_box(twin.env, twin.env.config)
    dt = twin.control_dt_s
    step = np.maximum(np.abs(low), np.abs(high))
    if twin.env.config.control_mode == "joint_velocity":
        step = step * dt
    speed = step / dt * (1.0 + CAP_MARGIN)
    return speed.tolist(), (2.0 * speed / dt).tolist()


def filter_configs(twin: SimulatorBackend, settings: dict | None,
                   robot_state: RobotState | None = None,
                   robot_accel_rad_s2: float | None = None) -> tuple[FilterConfig,
                                                                     FilterConfig | None]:
    """The twin filter's config (the twin's period, setpoint box, patient range and cuff
    limit, the env's caps of :func:`env_caps`, and ``settings`` on top: any field of
    :class:`~rehabbot.deploy.safety_filter.FilterConfig`) and, for a robot whose state is
    ``robot_state``, its own: the same without the range rule (the robot does not measure the
    patient's joints), without the force rule where the robot has no force estimate, with the
    robot's own joint range as its box (the approach to a start pose may cross outside the
    env's setpoint box, which the twin's filter keeps), no drop of a hold onto the measured
    position (a robot's interface refuses a jump of its command) and
    with the acceleration cap at most :data:`ROBOT_ACCEL_SHARE` of ``robot_accel_rad_s2``
    (the robot backend's own cap, which stops the robot).

    Raises:
        UsageError: an unknown field (the known ones are listed) or a bad value (naming it).
    """
    settings = dict(settings or {})
    known = [f.name for f in dataclasses.fields(FilterConfig) if f.name != "control_dt_s"]
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise UsageError(f"--filter-config: unknown setting(s) {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(known)}")
    speed, accel = env_caps(twin)
    twin_config = FilterConfig.for_simulator(
        twin, **{"max_speed_rad_s": speed, "max_accel_rad_s2": accel, **settings})
    if robot_state is None:
        return twin_config, None
    force = twin_config.cuff_force_limit_n if np.isfinite(robot_state.cuff_force_n) else None
    accel = np.broadcast_to(twin_config.max_accel_rad_s2, (len(twin.joint_names),))
    if robot_accel_rad_s2 is not None:
        accel = np.minimum(accel, ROBOT_ACCEL_SHARE * robot_accel_rad_s2)
    robot = twin.env.robot
    return twin_config, dataclasses.replace(
        twin_config, rom_low_rad=None, rom_high_rad=None, patient_joint_names=None,
        cuff_force_limit_n=force, max_accel_rad_s2=accel.tolist(),
        joint_low_rad=robot.joint_low_rad().tolist(),
        joint_high_rad=robot.joint_high_rad().tolist(), release_to_measured=False)


def open_robot(backend: str, robot_ip: str | None, twin: SimulatorBackend,
               watchdog_s: float | None = None) -> tuple[RobotBackend, float]:
    """Connect the robot of ``backend`` (``franka``, ``ur``) at ``robot_ip``, at the twin's
    decision period, with its servo loop's watchdog at ``watchdog_s`` (default: the
    backend's); returns it and its acceleration cap [rad/s^2].

    Raises:
        UsageError: an unknown backend, no address, or a twin of another robot.
    """
    if backend not in BACKENDS[1:]:
        raise UsageError(f"--backend {backend!r}: choose from {', '.join(BACKENDS)}")
    if not robot_ip:
        raise UsageError(f"--backend {backend} needs the robot's address: --robot-ip IP")
    robot_name = twin.env.robot.name
    wanted = {"franka": "fr3", "ur": "ur5e"}[backend]
    if robot_name != wanted:
        raise UsageError(f"--backend {backend} drives the {wanted}, but the policy's env has the "
                         f"{robot_name}: give --env-kwargs '{{\"robot\": \"{wanted}\"}}' (and a "
                         f"policy trained on it)")
    module = importlib.import_module(f"rehabbot.deploy.{backend}")
    cls = module.FrankaBackend if backend == "franka" else module.URBackend
    options = {} if watchdog_s is None else {"watchdog_s": watchdog_s}
    return (cls(robot_ip, control_dt_s=twin.control_dt_s, **options),
            module.MAX_ACCELERATION_RAD_S2)


def deploy(spec: str, out_dir: Path | str, backend: str = "sim", *, episodes: int = 1,
           seed: int | None = 0, env_id: str | None = None, env_kwargs: dict | None = None,
           filter_settings: dict | None = None, robot_ip: str | None = None,
           settings: SessionSettings | None = None,
           robot_watchdog_s: float | None = None) -> SessionResult:
    """``rehabbot deploy``: run the policy ``spec`` on ``backend`` through the safety filter
    for ``episodes`` episodes and log the session in ``out_dir``. Everything is checked (the
    policy loaded, the filter's settings, the output folder) before a robot is connected.

    Raises:
        UsageError, PolicyError, DataError: bad arguments, found before anything moves.
        SessionInterrupted, DeploymentError: as :meth:`DeploymentSession.run`.
    """
    if backend not in BACKENDS:
        raise UsageError(f"--backend {backend!r}: choose from {', '.join(BACKENDS)}")
    resolved, kwargs = policy_env(spec, env_id, env_kwargs)
    twin = SimulatorBackend(resolved, **kwargs)
    robot: RobotBackend | None = None
    try:
        policy = load_session_policy(spec, twin.wrapped)
        twin_config, _ = filter_configs(twin, filter_settings)
        check_session_folder(out_dir)
        settings = settings or SessionSettings()
        robot_info, robot_config = None, None
        if backend != "sim":
            robot, robot_accel = open_robot(backend, robot_ip, twin, robot_watchdog_s)
            robot_info = {"backend": backend, "address": robot_ip,
                          "joint_names": list(robot.joint_names),
                          "control_dt_s": robot.control_dt_s, "accel_cap_rad_s2": robot_accel}
            _, robot_config = filter_configs(twin, filter_settings, robot.state(), robot_accel)
        header = session_header(backend, policy, resolved, kwargs, twin, robot_info,
                                twin_config, robot_config, episodes, seed, settings)
        log = SessionLogWriter(out_dir, header, background=robot is not None)
        session = DeploymentSession(
            policy, twin, SafetyFilter(twin_config), robot=robot,
            robot_filter=SafetyFilter(robot_config) if robot_config is not None else None,
            log=log, settings=settings)
        return session.run(episodes, seed)
    finally:
        if robot is not None and hasattr(robot, "close"):
            robot.close()
        twin.close()
