"""RehabBot: MuJoCo simulation of robot-assisted physiotherapy for reinforcement learning.

A UR5e collaborative robot, strapped to a seated or supine humanoid patient's hand or shin,
moves the patient's shoulder, elbow, hip and knee through therapy exercises. Importing the
package registers the Gymnasium ids (:mod:`rehabbot.envs.registration`), prints nothing,
touches no network and loads neither PyTorch nor matplotlib.

The layers, each importing only those below it (``docs/architecture.md``):

============== =====================================================================
``sim``        robots, the patient, scenes, inverse kinematics, statics
``tasks``      exercises, targets, observation layout, reward terms, safety rules
``envs``       ``RehabEnv``, its validated config, controllers, rendering, the ids
``rl``         training (Stable-Baselines3, SBX), rollouts, policies, experts, zoo
``analysis``   clinical metrics, evaluation reports, traces, figures, video
``cli``        the ``rehabbot`` command
============== =====================================================================

The names most users need are here too, imported on first use: ``RehabEnv``,
``RehabEnvConfig``, ``PatientProfile``, ``PatientCondition``, ``PatientPopulation``,
``PopulationEnv``, ``Exercise``, ``ScriptedExpert``, ``AssistAsNeeded``.
"""

from __future__ import annotations

import importlib
from typing import Any

from rehabbot.common.version import VERSION
from rehabbot.envs.registration import register_envs

__version__ = VERSION

register_envs()

_LAZY = {
    "RehabEnv": "rehabbot.envs.rehab_env",
    "RehabEnvConfig": "rehabbot.envs.config",
    "PatientProfile": "rehabbot.sim.patient",
    "PatientCondition": "rehabbot.sim.conditions",
    "PatientPopulation": "rehabbot.sim.populations",
    "PopulationEnv": "rehabbot.envs.population",
    "Exercise": "rehabbot.tasks.exercises",
    "ScriptedExpert": "rehabbot.rl.experts",
    "AssistAsNeeded": "rehabbot.rl.assist_as_needed",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'rehabbot' has no attribute {name!r}")


__all__ = ["__version__", "register_envs", *_LAZY]
