"""Importing the package is quiet, light and offline."""

import subprocess
import sys

PROBE = """
import socket, sys
def refuse(*args, **kwargs):
    raise AssertionError("network access during import")
socket.socket.connect = refuse
socket.create_connection = refuse
import rehabbot
import rehabbot.sim, rehabbot.sim.ik, rehabbot.sim.statics, rehabbot.sim.paths
import rehabbot.tasks.targets, rehabbot.sim.physics, rehabbot.tasks.reward
import rehabbot.envs.rehab_env, rehabbot.envs.config
rehabbot.RehabEnv, rehabbot.PatientProfile, rehabbot.Exercise
HEAVY = ("torch", "stable_baselines3", "matplotlib", "imageio")
heavy = sorted(m for m in HEAVY if m in sys.modules)
print("HEAVY:" + ",".join(heavy), file=sys.stderr)
"""


def test_import_prints_nothing_and_loads_no_heavy_dependency():
    result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                            check=True)
    assert result.stdout == ""
    assert result.stderr.strip() == "HEAVY:"


def test_version_is_exposed_and_matches_the_installed_metadata():
    from importlib import metadata

    import rehabbot

    assert rehabbot.__version__.count(".") == 2
    assert metadata.version("rehabbot") == rehabbot.__version__


def test_the_common_names_are_importable_from_the_top():
    import rehabbot
    from rehabbot.envs.config import RehabEnvConfig
    from rehabbot.envs.rehab_env import RehabEnv
    from rehabbot.rl.experts import ScriptedExpert

    assert rehabbot.RehabEnv is RehabEnv and rehabbot.RehabEnvConfig is RehabEnvConfig
    assert rehabbot.ScriptedExpert is ScriptedExpert
    try:
        rehabbot.NoSuchThing  # noqa: B018
    except AttributeError as err:
        assert "NoSuchThing" in str(err)
    else:
        raise AssertionError("unknown top-level names must raise AttributeError")
