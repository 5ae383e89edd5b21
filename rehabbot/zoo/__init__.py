"""The zoo of trained agents shipped with RehabBot, run with NumPy alone.

::

    import gymnasium as gym
    import rehabbot.zoo

    print(rehabbot.zoo.available())              # [("rehabbot/rehab-reach-v1", "sac"), ...]
    agent = rehabbot.zoo.load("rehab-reach-v1", "ppo")
    env = gym.make(agent.env_id, **agent.metadata.get("env_kwargs", {}))
    obs, info = env.reset(seed=0)
    action, _ = agent.predict(obs)                # SB3's signature; deterministic only
    # The whole SBX/SB3 model, for .learn(): fetched once (rehabbot zoo fetch, docs/zoo.md)
    model = rehabbot.zoo.load_full_model("rehab-knee-v2", "sac")

This package is the data folder: ``<env-short-name>/<algo>.npz``, one file per agent (the
agents' full models are not shipped: :mod:`rehabbot.rl.zoo_full` fetches and loads them).
The loader lives in :mod:`rehabbot.rl.zoo` (the ``rl`` layer), which also builds the files
(``rehabbot zoo export RUN_DIR``) and documents their format; this module only re-exports
it. Importing it loads neither PyTorch nor JAX.
"""

from __future__ import annotations

from rehabbot.rl.zoo import (
    ZooError,
    ZooPolicy,
    available,
    load,
    load_file,
    zoo_dir,
)
from rehabbot.rl.zoo_full import fetch_full_model, find_full_model, load_full_model

__all__ = ["ZooError", "ZooPolicy", "available", "fetch_full_model", "find_full_model", "load",
           "load_file", "load_full_model", "zoo_dir"]
