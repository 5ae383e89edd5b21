"""The registered environment ids: one class (:class:`rehabbot.env.RehabEnv`), variants by
keyword arguments. ``import rehabbot`` calls :func:`register_envs`."""

from __future__ import annotations

import gymnasium as gym

ENTRY_POINT = "rehabbot.env:RehabEnv"
MAX_EPISODE_STEPS = 1000
# Gymnasium's PassiveEnvChecker (added by gym.make) breaks an env whose first reset() raised:
# after a reset with a bad option, the next good reset() and step() fail inside the checker
# with "TypeError: cannot unpack non-iterable NoneType object" (Gymnasium 1.4.0). Our test
# suite runs Gymnasium's full check_env on every id instead; gym.make(...,
# disable_env_checker=False) still adds the passive checker.
PASSIVE_CHECKER_DISABLED = True

# id -> (kwargs, one-line description); the paper's Table 2.
ENV_SPECS: dict[str, tuple[dict, str]] = {
    "rehabbot/rehab-reach-v0": (
        {"limb": "arm", "side": "right", "task_type": "reaching"},
        "right arm, seated: reach 6 shoulder or elbow key poses in order",
    ),
    "rehabbot/rehab-reach-l-v0": (
        {"limb": "arm", "side": "left", "task_type": "trajectory"},
        "left arm, seated: follow dense waypoints of a minimum-jerk shoulder or elbow path",
    ),
    "rehabbot/rehab-hip-v0": (
        {"limb": "hip", "side": "right", "task_type": "reaching"},
        "right leg, supine: reach 6 hip flexion/extension key poses in order",
    ),
    "rehabbot/rehab-knee-v0": (
        {"limb": "knee", "side": "right", "task_type": "trajectory"},
        "right leg, seated: follow dense waypoints of a minimum-jerk knee flexion/extension path",
    ),
}


def register_envs() -> None:
    """Register every id of :data:`ENV_SPECS` with Gymnasium (idempotent)."""
    for env_id, (kwargs, _description) in ENV_SPECS.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=ENTRY_POINT, kwargs=dict(kwargs),
                     max_episode_steps=MAX_EPISODE_STEPS,
                     disable_env_checker=PASSIVE_CHECKER_DISABLED)
