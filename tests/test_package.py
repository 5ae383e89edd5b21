"""Importing the package is quiet, light and offline."""

import subprocess
import sys

PROBE = """
import socket, sys
def refuse(*args, **kwargs):
    raise AssertionError("network access during import")
socket.socket.connect = refuse
socket.create_connection = refuse
import rehabbot, rehabbot.models, rehabbot.kinematics, rehabbot.statics
HEAVY = ("torch", "stable_baselines3", "matplotlib", "imageio")
heavy = sorted(m for m in HEAVY if m in sys.modules)
print("HEAVY:" + ",".join(heavy), file=sys.stderr)
"""


def test_import_prints_nothing_and_loads_no_heavy_dependency():
    result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                            check=True)
    assert result.stdout == ""
    assert result.stderr.strip() == "HEAVY:"


def test_version_is_exposed():
    import rehabbot

    assert rehabbot.__version__.count(".") == 2
