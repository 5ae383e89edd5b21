"""Narrow filters for the third-party warnings that the evaluator's and the renderer's own calls
set off, which say nothing a RehabBot user can act on:

* Gymnasium's ``DeprecationWarning`` "The environment rehabbot/rehab-reach-v1 is out of date.
  You should consider upgrading to version `v2`" when a ``-v0``/``-v1`` id is made: those ids
  are kept on purpose (the paper's env, the -v1 zoo), so the advice is wrong for them;
* TensorFlow Probability's ``DeprecationWarning`` "jax.core.pytype_aval_mappings is
  deprecated" when SBX (the JAX backend) is imported to load a model.

Only these messages, from these modules, and only around those calls (not a global filter).
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from typing import Any

import gymnasium as gym

OUT_OF_DATE_MESSAGE = r".*The environment \S+ is out of date\. You should consider upgrading"
JAX_DEPRECATION_MESSAGE = r"jax\.core\.\w+ is deprecated"


@contextlib.contextmanager
def quiet_known_warnings() -> Iterator[None]:
    """Within the block: the two known third-party warnings above are not shown."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=OUT_OF_DATE_MESSAGE,
                                category=DeprecationWarning, module=r"gymnasium(\.|$)")
        warnings.filterwarnings("ignore", message=JAX_DEPRECATION_MESSAGE,
                                category=DeprecationWarning,
                                module=r"(tensorflow_probability|jax|sbx)(\.|$)")
        yield


def make_env(env_id: str, **kwargs: Any) -> gym.Env:
    """``gym.make(env_id, **kwargs)`` without Gymnasium's "out of date" warning for the
    ids kept on purpose (``-v0``, ``-v1``)."""
    with quiet_known_warnings():
        return gym.make(env_id, **kwargs)
