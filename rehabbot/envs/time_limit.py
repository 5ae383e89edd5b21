"""The env's horizon is ``gym.make``'s time limit.

The horizon is the config's ``max_episode_steps`` (task group), registered per id as a keyword
argument, so ``gym.make(id)`` builds the env with the registered horizon. ``gym.make(id,
max_episode_steps=m)`` gives ``m`` to Gymnasium's ``TimeLimit`` wrapper only, never to the
env's constructor; every id therefore registers :func:`adopt_time_limit` as an
``additional_wrappers`` entry, which ``gym.make`` calls with the env it has just wrapped in its
``TimeLimit``. It hands the limit to the env's ``set_time_limit`` and returns the env
unchanged (it adds no wrapper).

The rules it applies:

* ``m`` must be a positive integer in the config's range (``ValueError`` naming it).
  Gymnasium's ``TimeLimit`` itself refuses ``m = 0``, a negative ``m`` and a non-integer.
* No ``TimeLimit`` (Gymnasium's ``max_episode_steps=-1``) is refused: the safety penalty
  counts the steps left to the horizon.
* A condition variant (:data:`rehabbot.envs.registration.CONDITION_VARIANTS`) refuses a
  ``condition=`` that replaces its own (``condition=None`` would silently give a healthy
  patient).

A spec without this entry (``gym.make(env.unwrapped.spec)``, as Gymnasium's env checker and
vector envs do) builds the env with the horizon in its keyword arguments, and the ``spec`` of
the env ``gym.make`` returns records the adopted horizon in its keyword arguments, so that
making an env again from it gives the same horizon.
"""

from __future__ import annotations

import gymnasium as gym

from rehabbot.envs.registration import CONDITION_VARIANTS


def check_variant_condition(env_id: str | None, kwargs: dict) -> None:
    """Refuse (``ValueError``) a condition variant id made with a ``condition`` other than the
    variant's own (``kwargs``: the keyword arguments the env was built with)."""
    if env_id not in CONDITION_VARIANTS or "condition" not in kwargs:
        return
    from rehabbot.sim.conditions import as_condition  # the env module imports this one

    given = kwargs["condition"]
    base_id, own, _description = CONDITION_VARIANTS[env_id]
    if as_condition(given) != as_condition(own):
        raise ValueError(
            f"condition={given!r} would replace the condition of {env_id} ({own}); make the "
            f"base id with a condition instead: gym.make({base_id!r}, condition=...)")


def made_time_limit(env: gym.Env) -> int:
    """The ``max_episode_steps`` of the ``TimeLimit`` that ``gym.make`` wrapped ``env`` in.

    Raises:
        ValueError: no ``TimeLimit`` (``max_episode_steps=-1``) or a limit that is not a
            positive integer.
    """
    spec = env.spec
    limit = None if spec is None else spec.max_episode_steps
    if limit is None:
        limit = -1
    if isinstance(limit, bool) or not isinstance(limit, int) or limit <= 0:
        raise ValueError(
            f"max_episode_steps={limit!r} must be a positive integer (the episode's time "
            "limit; -1, Gymnasium's 'no time limit', is refused: the safety penalty counts the "
            "steps left to the limit)")
    return limit


def adopt_time_limit(env: gym.Env) -> gym.Env:
    """Give ``env.unwrapped`` the time limit ``gym.make`` wrapped it in as its horizon (see the
    module docstring) and return ``env`` itself. A refused limit or condition closes the env
    and raises ``ValueError``."""
    base = env.unwrapped
    made_spec = base.spec
    try:
        check_variant_condition(getattr(made_spec, "id", None),
                                dict(getattr(made_spec, "kwargs", None) or {}))
        limit = made_time_limit(env)
        base.set_time_limit(limit)
    except ValueError:
        env.close()
        raise
    if env.spec is not None:  # what gym.make(env.spec) builds again: the same horizon
        env.spec.kwargs["max_episode_steps"] = limit
    return env
