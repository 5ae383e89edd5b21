"""The simulated world, built in code with ``mujoco.MjSpec``: robots (:mod:`.robots`), the
parametric patient (:mod:`.patient`) and the scenes that join them (:mod:`.scene`,
:mod:`.scene_build`), with the coupled kinematics (:mod:`.ik`, :mod:`.paths`), statics
(:mod:`.statics`) and the scripted sweep (:mod:`.scripted_sweep`).

This layer knows nothing of exercises, rewards or RL.
"""

from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.scene import PRESETS, Scene, SceneOptions
from rehabbot.sim.scene_build import build_scene

__all__ = ["PRESETS", "PatientProfile", "Scene", "SceneOptions", "build_scene"]
