"""The batched backend (issue 29, first part): the ``-v2`` ids as functional JAX envs on
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

from rehabbot.batch.env import BatchedRehabEnv
from rehabbot.batch.state import State
from rehabbot.batch.tables import RULE_CODES, SUPPORTED_IDS
from rehabbot.batch.vector import BatchedVectorEnv, make_vec, register_vector_entry_points


def make(env_id: str, **kwargs: Any) -> BatchedRehabEnv:
    """The batched env of ``env_id``, built from ``gym.make(env_id, **kwargs)``; ``naconmax``
    and ``njmax`` (see :class:`BatchedRehabEnv`) are the batched env's own keywords.

    Raises:
        ValueError: an id, keyword or condition that is not batched yet (named).
    """
    return BatchedRehabEnv(env_id, **kwargs)


__all__ = ["RULE_CODES", "SUPPORTED_IDS", "BatchedRehabEnv", "BatchedVectorEnv", "State", "make",
           "make_vec", "register_vector_entry_points"]
