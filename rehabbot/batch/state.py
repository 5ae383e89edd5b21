"""The batched env's state: MuJoCo Playground's ``State`` (``data, obs, reward, done,
metrics, info``), a pytree that ``jax.jit``, ``jax.vmap`` and ``jax.lax.scan`` carry."""

from __future__ import annotations

from typing import Any

import jax
from flax import struct


@struct.dataclass
class State:
    """One world's state (a batch of them under ``jax.vmap``).

    Attributes:
        data: the MJX data (``impl="warp"``) of the world.
        obs: the ``-v2`` agent observation (float32).
        reward: the step's reward (float32 scalar).
        done: 1.0 when the episode ended (a safety stop, the last target reached, or the time
            limit: ``info["truncation"]`` says which), else 0.0.
        metrics: per-step readings (``interaction_force_n``, ``cost``, ``safety_violation``
            (0 none, else 1 + the index of the rule in :data:`rehabbot.sim.physics.RULES`),
            ``is_success``, ``target_index``, the work entries, the reward terms
            ``reward_*``).
        info: the episode's own state the next step needs (setpoints, target index, exercise,
            steps, the reward's path left and hold gap, the last healthy joint angles and
            observation fields, the random key, ``truncation``; with a condition that applies
            torques, the patient drive's delay lines, tremor and work:
            :class:`rehabbot.batch.patient_drive.BatchedPatientDrive`).
    """

    data: Any
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    metrics: dict[str, jax.Array]
    info: dict[str, Any]
