"""From the simulator to a real robot: policies exported to ONNX (:mod:`rehabbot.rl.onnx_export`),
a deployment safety filter between any policy and any robot (:mod:`rehabbot.deploy.safety_filter`),
robot backends behind one small interface (:mod:`rehabbot.deploy.backend`), a deployment loop
that logs a session (:mod:`rehabbot.deploy.session`) and patient calibration
(:mod:`rehabbot.deploy.calibration`). See ``docs/deployment/index.md``.

Nothing here is imported by ``import rehabbot``; the robot libraries (``pylibfranka``,
``ur_rtde``) are imported inside the backends that need them.
"""
