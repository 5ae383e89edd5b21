"""Start and stop franka-sim (the libfranka network protocol on MuJoCo) on 127.0.0.1: the robot
the Franka backend's tests, its benchmark and the deployment tutorial drive.

franka-sim 1.1.7 pins numpy 1.26.4 and MuJoCo < 3.3, so it lives in its own venv,
``.venv-franka-sim`` at the repository root (``tools/franka-sim-venv.sh`` makes it; the
environment variable ``REHABBOT_FRANKA_SIM_PYTHON`` names another venv's Python). This module
imports nothing of rehabbot: the sim venv runs it as a script. It loads
its FR3 from MuJoCo Menagerie through ``robot_descriptions``, which downloads the Menagerie on
first use; to run offline this module builds the arm from the URDF that ships inside the
franka-sim wheel (``franka_sim/models/fr3.urdf``, the model the server also serves to
libfranka): kinematics, masses, inertias and joint limits as published there, meshes dropped
(the server's self-collision check is then off: there are no collision geoms) and a joint
armature of 0.1 kg m^2 (the Menagerie FR3's), which the server's 1 kHz explicit PD servo needs
to be stable. ``$FR3_MJCF`` points the server at that file.

Run as a script with the sim venv's Python, it writes the model and serves on 127.0.0.1:1337
(the port libfranka always uses) with the FCI's motion limits enforced (a discontinuous or
too fast setpoint stream aborts the motion, as on the robot) and no gripper.
:func:`franka_sim_server` starts that as a subprocess and stops it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SIM_PYTHON = Path(os.environ.get("REHABBOT_FRANKA_SIM_PYTHON",
                                 REPO / ".venv-franka-sim" / "bin" / "python"))
HOST = "127.0.0.1"
PORT = 1337
ARMATURE_KG_M2 = 0.5
START_TIMEOUT_S = 60.0
PORT_WAIT_S = 15.0


def offline_mjcf(path: Path) -> Path:
    """Write the FR3 MJCF built from franka-sim's own URDF (module docstring) to ``path``."""
    import xml.etree.ElementTree as ET

    import franka_sim
    import mujoco

    urdf = Path(franka_sim.__file__).parent / "models" / "fr3.urdf"
    root = ET.parse(urdf).getroot()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    options = ET.SubElement(root, "mujoco")
    ET.SubElement(options, "compiler", discardvisual="true", fusestatic="false")
    spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    for joint in spec.joints:
        joint.armature = ARMATURE_KG_M2
    spec.compile()
    path.write_text(spec.to_xml())
    return path


def serve() -> None:
    """The server, in the sim venv (blocks until SIGTERM or SIGINT)."""
    from franka_sim import FrankaSimServer

    folder = Path(tempfile.mkdtemp(prefix="franka-sim-"))
    os.environ["FR3_MJCF"] = str(offline_mjcf(folder / "fr3_offline.xml"))
    server = FrankaSimServer(host=HOST, port=PORT, enable_gripper=False,
                             enforce_motion_limits=True)
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    try:
        server.start()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()


#: Scheduling niceness of the server (and, in the tests, of the client): a 1 kHz loop shares
#: the machine's cores with whatever else runs; raising its priority needs root (else kept).
NICENESS = -10


def _raise_priority() -> None:
    with contextlib.suppress(PermissionError):
        os.setpriority(os.PRIO_PROCESS, 0, NICENESS)


def _port_open() -> bool:
    with socket.socket() as probe:
        probe.settimeout(0.2)
        return probe.connect_ex((HOST, PORT)) == 0


@contextlib.contextmanager
def franka_sim_server(log_path: Path) -> Iterator[subprocess.Popen]:
    """Run the server (a subprocess of the sim venv's Python, its output in ``log_path``)
    until the block ends; raise RuntimeError if it does not listen within a minute."""
    deadline = time.monotonic() + PORT_WAIT_S
    while _port_open():  # a server just stopped may still be closing
        if time.monotonic() > deadline:
            raise RuntimeError(f"{HOST}:{PORT} is in use: another franka-sim or FCI server "
                               "runs here")
        time.sleep(0.2)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": ""}
    with open(log_path, "wb") as log:
        process = subprocess.Popen([str(SIM_PYTHON), str(Path(__file__).resolve())],
                                   stdout=log, stderr=subprocess.STDOUT, env=env,
                                   cwd=str(log_path.parent), preexec_fn=_raise_priority)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not _port_open():
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"franka-sim did not start (exit {process.poll()}); its "
                                   f"log: {log_path}:\n{log_path.read_text()[-2000:]}")
            time.sleep(0.2)
        time.sleep(1.0)  # the physics loop starts after the socket listens
        yield process
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=PORT_WAIT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        deadline = time.monotonic() + PORT_WAIT_S
        while _port_open() and time.monotonic() < deadline:
            time.sleep(0.2)


if __name__ == "__main__":
    sys.exit(serve())
