"""Making a muscle (``-myo-``) id leaves nothing where it is run: no ``MUJOCO_LOG.TXT`` (MuJoCo's
default warning handler writes one for myo-sim's empty-prefix attachments), nothing printed, no
warning; and the MuJoCo warning handler that makes it so drops only what it is told to."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.sim.mujoco_warnings import MujocoWarning, handling_mujoco_warnings

MYO_IDS = sorted(env_id for env_id in gym.registry
                 if env_id.startswith("rehabbot/") and "-myo-" in env_id)
REPO = Path(__file__).resolve().parents[1]


def test_there_are_myo_ids():
    assert len(MYO_IDS) >= 3


@pytest.mark.parametrize("env_id", [
    pytest.param(env_id, marks=[] if "knee" in env_id else [pytest.mark.slow])
    for env_id in MYO_IDS])
@pytest.mark.slow
def test_making_a_myo_id_leaves_no_file_and_prints_nothing(env_id, tmp_path):
    """In a fresh process (myo-sim's model is composed once per process), in an empty folder,
    with every warning shown: make, reset and step the id."""
    pytest.importorskip("myo_sim", reason='the -myo- ids need pip install "rehabbot[myo]"')
    code = ("import gymnasium as gym, numpy as np, rehabbot; "
            f"env = gym.make({env_id!r}); env.reset(seed=0); "
            "[env.step(np.zeros(env.action_space.shape, np.float32)) for _ in range(3)]; "
            f"env.close(); gym.make({env_id!r}).close()")
    env = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl"}
    result = subprocess.run([sys.executable, "-W", "always", "-c", code], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout == "" and result.stderr == "", (result.stdout, result.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def _warn_bad_qpos() -> None:
    """A MuJoCo C warning (a NaN position) through mju_warning."""
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><joint/><geom size='0.1'/></body></worldbody></mujoco>")
    data = mujoco.MjData(model)
    data.qpos[0] = np.nan
    mujoco.mj_checkPos(model, data)


def test_the_handler_drops_only_the_named_warnings(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = mujoco.get_mju_user_warning()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with handling_mujoco_warnings("QPOS"):
            _warn_bad_qpos()
        assert caught == []
        with handling_mujoco_warnings("something else"):
            _warn_bad_qpos()
    assert [w.category for w in caught] == [MujocoWarning]
    assert "MuJoCo: " in str(caught[0].message) and "QPOS" in str(caught[0].message)
    assert mujoco.get_mju_user_warning() is before
    assert list(tmp_path.iterdir()) == []


def test_the_handler_passes_other_warnings_to_the_previous_handler():
    before = mujoco.get_mju_user_warning()
    received: list[str] = []
    mujoco.set_mju_user_warning(received.append)
    try:
        with handling_mujoco_warnings("something else"):
            _warn_bad_qpos()
        assert len(received) == 1 and "QPOS" in received[0]
        with handling_mujoco_warnings("QPOS"):
            _warn_bad_qpos()
        assert len(received) == 1
        _warn_bad_qpos()  # the previous handler is back
        assert len(received) == 2
    finally:
        mujoco.set_mju_user_warning(before)


@pytest.mark.parametrize("dropped", [(), ("",), (3,)])
def test_the_handler_needs_texts(dropped):
    with pytest.raises(ValueError, match="dropped="), handling_mujoco_warnings(*dropped):
        pass
