"""Models built in code: the UR5e, the parametric patient and the scenes that join them."""

from rehabbot.models.patient import PatientProfile
from rehabbot.models.scene import PRESETS, Scene, SceneOptions, build_scene

__all__ = ["PRESETS", "PatientProfile", "Scene", "SceneOptions", "build_scene"]
