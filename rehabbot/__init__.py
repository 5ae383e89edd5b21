"""RehabBot: MuJoCo simulation of robot-assisted physiotherapy for reinforcement learning.

A UR5e collaborative robot, strapped to a seated or supine humanoid patient's hand or ankle,
moves the patient's shoulder, elbow, hip and knee. Models are built in code
(:mod:`rehabbot.models`); importing the package registers the Gymnasium ids
(:mod:`rehabbot.registration`), prints nothing and touches no network.
"""

from rehabbot.registration import register_envs

__version__ = "0.1.0"

register_envs()

__all__ = ["__version__", "register_envs"]
