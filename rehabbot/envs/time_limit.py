"""The env takes ``gym.make``'s time limit as its own horizon.

``gym.make(id, max_episode_steps=m)`` wraps the env in a ``TimeLimit`` of ``m`` steps but
never tells the env, whose safety penalty counts the steps left to its horizon. Gymnasium sets
the env's ``spec`` right after building it, from inside ``make``:
:func:`rehabbot.envs.registration.check_make` reads the limit there, and the setter hands it
to the env's ``set_time_limit``.
"""

from __future__ import annotations

import sys

import gymnasium as gym

from rehabbot.envs.registration import check_make


class MakeTimeLimit:
    """Mixin of the env classes: a ``spec`` property whose setter adopts ``gym.make``'s time
    limit (``set_time_limit``) and closes the env before re-raising a refused one."""

    @property
    def spec(self) -> gym.envs.registration.EnvSpec | None:
        """The spec ``gym.make`` gave the env (None when built directly)."""
        return self.__dict__.get("_spec")

    @spec.setter
    def spec(self, spec: gym.envs.registration.EnvSpec | None) -> None:
        try:
            limit = None if spec is None else check_make(spec, sys._getframe(1))
            if limit is not None:
                self.set_time_limit(limit)
        except ValueError:
            self.close()
            raise
        self.__dict__["_spec"] = spec

    def set_time_limit(self, max_episode_steps: int) -> None:
        raise NotImplementedError
