"""The batched backend: the ``-v2`` ids as functional JAX envs on
MuJoCo Warp (through MJX, ``impl="warp"``), in MuJoCo Playground's interface.

``import rehabbot`` never imports this package (nor JAX or Warp); it needs the ``[gpu]``
extra (``pip install "rehabbot[gpu]"``). See ``docs/batch.md``.

Example::

    import jax
    import rehabbot.batch

    env = rehabbot.batch.make("rehabbot/rehab-reach-v2", naconmax=16 * 1024)
    reset, step = jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))
    state = reset(jax.random.split(jax.random.key(0), 1024))
    state = step(state, jax.numpy.zeros((1024, env.action_size)))
"""

from __future__ import annotations

from typing import Any

import warp

from rehabbot.common.native_output import dropping_stderr_lines

# Warp logs its start and every kernel module it compiles or loads, and its native library
# warns on a machine without a CUDA driver (the CPU device still runs). RehabBot prints
# nothing: Warp's log shows errors only (set warp.config.log_level = warp.LOG_INFO after
# importing rehabbot.batch to see the rest), and the driver warning is dropped at init.
warp.config.log_level = warp.LOG_ERROR
NO_CUDA_DRIVER_WARNING = "Could not find or load the NVIDIA CUDA driver"
with dropping_stderr_lines(NO_CUDA_DRIVER_WARNING):
    warp.init()

from rehabbot.batch.env import BatchedRehabEnv  # noqa: E402
from rehabbot.batch.env_tables import BATCHED_IDS, RULE_CODES, SUPPORTED_IDS  # noqa: E402
from rehabbot.batch.state import State  # noqa: E402
from rehabbot.batch.vector import BatchedVectorEnv, make_vec, register_vector_entry_points  # noqa: E402


def make(env_id: str, **kwargs: Any) -> BatchedRehabEnv:
    """The batched env of ``env_id``, built from ``gym.make(env_id, **kwargs)``; ``naconmax``
    and ``njmax`` (see :class:`BatchedRehabEnv`) are the batched env's own keywords.

    Raises:
        ValueError: an id, keyword or condition that is not batched yet (named).
    """
    return BatchedRehabEnv(env_id, **kwargs)


__all__ = ["BATCHED_IDS", "RULE_CODES", "SUPPORTED_IDS", "BatchedRehabEnv", "BatchedVectorEnv",
           "State", "make", "make_vec", "register_vector_entry_points"]
