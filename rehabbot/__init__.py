"""RehabBot: MuJoCo simulation of robot-assisted physiotherapy for reinforcement learning.

A UR5e collaborative robot, strapped to a seated or supine humanoid patient's hand or ankle,
moves the patient's shoulder, elbow, hip and knee. Models are built in code
(:mod:`rehabbot.models`); importing the package prints nothing and touches no network.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
