"""The environments: :class:`RehabEnv` (:mod:`.rehab_env`), its validated configuration
(:mod:`.config`), the two-arm :class:`BilateralEnv` (:mod:`.bilateral_env`), one controller
per control mode (:mod:`.control`), rendering (:mod:`.rendering`, :mod:`.overlay`) and the
registered ids (:mod:`.registration`).

``RehabEnv``, ``RehabEnvConfig`` and ``BilateralEnv`` are imported on first use, so that
``import rehabbot`` (which registers the ids) stays light.
"""

from __future__ import annotations

from typing import Any

from rehabbot.envs.registration import ENV_SPECS, env_short_name, register_envs, resolve_env_id


def __getattr__(name: str) -> Any:
    if name == "RehabEnv":
        from rehabbot.envs.rehab_env import RehabEnv

        return RehabEnv
    if name == "RehabEnvConfig":
        from rehabbot.envs.config import RehabEnvConfig

        return RehabEnvConfig
    if name == "BilateralEnv":
        from rehabbot.envs.bilateral_env import BilateralEnv

        return BilateralEnv
    raise AttributeError(f"module 'rehabbot.envs' has no attribute {name!r}")


__all__ = ["ENV_SPECS", "BilateralEnv", "RehabEnv", "RehabEnvConfig", "env_short_name",
           "register_envs", "resolve_env_id"]
