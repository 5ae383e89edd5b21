"""Policies exported to ONNX (``rehabbot.rl.onnx_export``, ``rehabbot export``): onnxruntime's
actions equal the zoo agent's and the Stable-Baselines3 model's within 1e-5 on recorded
episodes, a changed weight is caught by that comparison, the metadata describes the env, the
robot and the patient, and bad input (an unknown policy or format, an unwritable ``--out``, a
missing extra) is refused by name, leaving nothing behind."""

from __future__ import annotations

import errno
import json
import os
import re
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.common.errors import DataError, UsageError
from rehabbot.common.version import VERSION
from rehabbot.rl import onnx_export, zoo
from rehabbot.rl.onnx_export import (
    METADATA_KEYS,
    OnnxExportError,
    export_onnx,
    load_onnx_policy,
    record_observations,
)

AGENT = "zoo:rehab-knee-v2/sac"
ENV_ID = "rehabbot/rehab-knee-v2"
TOLERANCE = 1e-5
MIN_OBSERVATIONS = 1000
HINT = 'pip install "rehabbot[onnx]"'


@pytest.fixture(scope="module")
def knee(tmp_path_factory) -> tuple[Path, dict, zoo.ZooPolicy, np.ndarray]:
    """The knee SAC agent exported, and the observations of its own episodes (>= 1000)."""
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    out = tmp_path_factory.mktemp("onnx") / "knee-sac.onnx"
    meta = export_onnx(AGENT, out)
    agent = zoo.load_spec(AGENT)
    observations = record_observations(agent, agent.env_id, {}, episodes=2, seed=0,
                                       at_least=MIN_OBSERVATIONS)
    return out, meta, agent, observations


def max_gap(policy, reference, observations: np.ndarray) -> float:
    return float(np.max(np.abs(policy.predict(observations)[0]
                               - reference.predict(observations, deterministic=True)[0])))


# --------------------------------------------------------------------------- parity


def test_onnx_actions_equal_the_zoo_agents_on_its_recorded_episodes(knee) -> None:
    out, _meta, agent, observations = knee
    policy = load_onnx_policy(out)
    assert len(observations) >= MIN_OBSERVATIONS
    actions, state = policy.predict(observations)
    assert state is None and actions.dtype == np.float32
    assert actions.shape == (len(observations), agent.action_space.shape[0])
    assert max_gap(policy, agent, observations) <= TOLERANCE
    assert np.ptp(actions, axis=0).min() > 0.1  # the episodes exercise the network
    for obs in observations[:: len(observations) // 5]:  # one observation, not a batch
        single = policy(obs)
        assert single.shape == agent.action_space.shape
        assert np.max(np.abs(single - agent(obs))) <= TOLERANCE


def test_a_changed_weight_in_the_file_changes_its_actions_beyond_the_tolerance(
        knee, tmp_path) -> None:
    """The parity comparison catches a real change: one weight of the first layer moved by
    1 % of its value."""
    import onnx
    from onnx import numpy_helper

    out, _meta, agent, observations = knee
    model = onnx.load(out)
    gemm = next(node for node in model.graph.node if node.op_type == "Gemm")
    tensor = next(t for t in model.graph.initializer if t.name == gemm.input[1])
    weight = numpy_helper.to_array(tensor).copy()
    index = np.unravel_index(np.argmax(np.abs(weight)), weight.shape)
    weight[index] *= np.float32(1.01)
    tensor.CopyFrom(numpy_helper.from_array(weight, tensor.name))
    onnx.save(model, tmp_path / "changed.onnx")
    assert max_gap(load_onnx_policy(tmp_path / "changed.onnx"), agent,
                   observations) > TOLERANCE
    assert max_gap(load_onnx_policy(out), agent, observations) <= TOLERANCE


def test_export_refuses_a_graph_that_does_not_act_as_the_policy(monkeypatch,
                                                                tmp_path) -> None:
    """A wrong translation (tanh written as a sigmoid) is caught before anything is
    written."""
    pytest.importorskip("onnxruntime")
    translate = onnx_export._add_step

    def sigmoid_for_tanh(g, x, name, params, size):
        return translate(g, x, "sigmoid" if name == "tanh" else name, params, size)

    monkeypatch.setattr(onnx_export, "_add_step", sigmoid_for_tanh)
    with pytest.raises(OnnxExportError, match=r"differ from the policy's by .*nothing was "
                                              r"written"):
        export_onnx("zoo:rehab-knee-v2/ppo", tmp_path / "wrong.onnx")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_v1_agent_and_a_run_folder_go_through_the_zoo_program(tmp_path) -> None:
    """A -v1 agent (its tracking-error step) and a run folder (a batched run's actor,
    exported through ``zoo_export`` as ``rehabbot zoo export`` reads it) act as their zoo
    programs."""
    pytest.importorskip("onnxruntime")
    v1 = zoo.load_spec("zoo:rehab-knee-v1/sac")
    assert v1.ops[0] == "tracking_error"
    export_onnx("zoo:rehab-knee-v1/sac", tmp_path / "v1.onnx")
    observations = record_observations(v1, v1.env_id, {}, episodes=1, seed=0)
    assert max_gap(load_onnx_policy(tmp_path / "v1.onnx"), v1, observations) <= TOLERANCE
    agent = zoo.load_spec("zoo:rehab-knee-v2/ppo")
    run = tmp_path / "run"
    run.mkdir()
    zoo.write_zoo_file(run / "policy.npz", agent.program(), agent.observation_space,
                       agent.action_space, {"env_id": ENV_ID, "algo": "ppo",
                                            "backend": "rsl_rl"})
    (run / "manifest.json").write_text(json.dumps({"env_id": ENV_ID, "algo": "ppo",
                                                   "seed": 4, "backend": "rsl_rl"}))
    meta = export_onnx(run, tmp_path / "run.onnx")
    assert meta["source"] == str(run) and meta["agent_metadata"]["seed"] == 4
    assert meta["weights_sha256"] == agent.metadata["weights_sha256"]
    observations = record_observations(agent, ENV_ID, {}, episodes=1, seed=0)
    assert max_gap(load_onnx_policy(tmp_path / "run.onnx"), agent, observations) <= TOLERANCE


# --------------------------------------------------------------------------- metadata


def test_the_metadata_describes_the_env_the_robot_and_the_patient(knee) -> None:
    import onnx

    out, meta, agent, _observations = knee
    env = gym.make(ENV_ID)
    base = env.unwrapped
    loaded = load_onnx_policy(out).metadata
    assert loaded == json.loads(json.dumps(meta)) and tuple(loaded) == METADATA_KEYS
    model = onnx.load(out)
    props = {p.key: json.loads(p.value) for p in model.metadata_props}  # every value: JSON
    assert props == loaded
    assert [o.version for o in model.opset_import] == [onnx_export.OPSET]
    (source,) = model.graph.input
    dims = source.type.tensor_type.shape.dim
    assert dims[0].dim_param == "batch" and dims[1].dim_value == 50
    assert loaded["source"] == AGENT and loaded["env_id"] == ENV_ID
    assert loaded["env_kwargs"] == {} and loaded["rehabbot_version"] == VERSION
    assert loaded["weights_sha256"] == agent.metadata["weights_sha256"]
    assert loaded["agent_metadata"]["weights_sha256"] == agent.metadata["weights_sha256"]
    assert loaded["control_dt_s"] == base.dt and loaded["control_rate_hz"] == 1 / base.dt
    names = loaded["observation_names"]
    assert len(names) == env.observation_space.shape[0] == len(set(names))
    assert names[:2] == ["joint_error_fine[shoulder_pan]", "joint_error_fine[shoulder_lift]"]
    assert names[12:15] == ["tool_error_fine[x]", "tool_error_fine[y]", "tool_error_fine[z]"]
    assert names[42:] == ["phi_in_range[hip_flexion_r]", "phi_in_range[hip_abduction_r]",
                          "phi_in_range[knee_flexion_r]", "cuff_force",
                          "exercise[knee_extension]", "exercise[knee_flexion_cycles]",
                          "weight_level", "target_progress"]
    assert loaded["action_low"] == env.action_space.low.tolist() == [-1.0] * 6
    assert loaded["action_high"] == env.action_space.high.tolist()
    assert loaded["controller_action_high"] == base.controller.clip_high.tolist()
    assert loaded["robot"] == "ur5e" and loaded["control_mode"] == "joint_delta"
    assert loaded["robot_joint_names"] == list(base.robot.joint_names) == \
        loaded["action_names"]
    assert loaded["cuff_force_limits_n"] == base.safety.force_limits_n.tolist() == [130.0]
    low, high = base.safety.rom_bounds_rad
    knee_index = base.scene.patient_joint_names.index("knee_flexion_r")
    rom = loaded["range_of_motion_rad"]
    assert list(rom) == ["hip_flexion_r", "hip_abduction_r", "knee_flexion_r"]
    assert rom["knee_flexion_r"] == [low[knee_index], high[knee_index]]
    assert loaded["rom_tolerance_deg"] == 2.0 and loaded["ops"] == list(agent.ops)


def test_an_fr3_agent_names_its_seven_joints_and_its_env_kwargs(tmp_path) -> None:
    pytest.importorskip("onnxruntime")
    meta = export_onnx("zoo:rehab-hip-v2/ppo-fr3", tmp_path / "fr3.onnx")
    assert meta["robot"] == "fr3" and meta["env_kwargs"] == {"robot": "fr3"}
    assert meta["robot_joint_names"] == [f"fr3_joint{k}" for k in range(1, 8)]
    assert len(meta["observation_names"]) == 56
    assert meta["observation_names"][6] == "joint_error_fine[fr3_joint7]"
    assert list(meta["range_of_motion_rad"]) == ["hip_flexion_r", "hip_abduction_r",
                                                 "knee_flexion_r"]


# --------------------------------------------------------------------------- the command


def test_export_command_writes_the_file_and_its_help_says_how(tmp_path, capsys) -> None:
    pytest.importorskip("onnxruntime")
    from rehabbot.cli import main

    out = tmp_path / "hip.onnx"
    assert main(["export", "zoo:rehab-hip-v2/ppo", "--format", "onnx", "--out",
                 str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(f"wrote {out}: zoo:rehab-hip-v2/ppo for rehabbot/rehab-hip-v2 "
                              "(ur5e, joint_delta), 50 observations -> 6 actions at 50 Hz")
    assert load_onnx_policy(out).metadata["source"] == "zoo:rehab-hip-v2/ppo"
    with pytest.raises(SystemExit) as stop:
        main(["export", "--help"])
    text = capsys.readouterr().out
    assert stop.value.code == 0
    for part in ("zoo:ENV/AGENT", "--format {onnx}", "--out FILE.onnx", "examples:",
                 "docs/deployment/export.md", HINT):
        assert part in text, part


def _no_space(*_args) -> None:
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_bad_input_is_refused_by_name_and_leaves_nothing(tmp_path, capsys,
                                                        monkeypatch) -> None:
    pytest.importorskip("onnxruntime")
    from rehabbot.cli import main

    out = str(tmp_path / "p.onnx")
    cases = [
        (["zoo:rehab-knee-v2/nosuch"], 2, "the zoo has no agent rehab-knee-v2/nosuch"),
        ([str(tmp_path / "nowhere")], 2, f"unknown policy {str(tmp_path / 'nowhere')!r}"),
        (["expert"], 2, "policy 'expert' is a scripted controller"),
        ([AGENT, "--env", "rehab-hip-v2"], 2,
         f"--env 'rehab-hip-v2': the zoo agent {AGENT} runs in the env it was trained in"),
    ]
    for argv, code, message in cases:
        assert main(["export", *argv, "--out", out]) == code, argv
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["export", AGENT, "--format", "tflite", "--out", out])
    assert stop.value.code == 2 and "invalid choice: 'tflite'" in capsys.readouterr().err
    with pytest.raises(UsageError, match="unknown export format 'tflite'"):
        export_onnx(AGENT, out, format="tflite")
    missing = tmp_path / "no" / "such" / "p.onnx"
    assert main(["export", AGENT, "--out", str(missing)]) == 2
    assert f"its folder {str(missing.parent)!r} does not exist" in capsys.readouterr().err
    (tmp_path / "a-file").write_text("")
    assert main(["export", AGENT, "--out", str(tmp_path / "a-file" / "p.onnx")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["export", AGENT, "--out", str(tmp_path / "p.txt")]) == 2
    assert f"--out {str(tmp_path / 'p.txt')!r}: the file must end in .onnx" in \
        capsys.readouterr().err
    with monkeypatch.context() as patch:  # a full disk: the write fails, naming the file
        patch.setattr(os, "fsync", _no_space)
        assert main(["export", AGENT, "--out", out]) == 1
    assert f"cannot write {out!r}: No space left on device" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


def test_a_missing_extra_names_the_pip_install(monkeypatch, tmp_path, capsys) -> None:
    from rehabbot.cli import main

    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # import onnxruntime fails
    with pytest.raises(UsageError, match=re.escape(f"need onnxruntime, which is not "
                                                   f"installed: {HINT}")):
        export_onnx(AGENT, tmp_path / "p.onnx")
    with pytest.raises(UsageError, match="onnxruntime"):
        load_onnx_policy(tmp_path / "p.onnx")
    assert main(["export", AGENT, "--out", str(tmp_path / "p.onnx")]) == 1
    err = capsys.readouterr().err
    assert "rehabbot export --format onnx needs onnxruntime" in err and HINT in err
    assert list(tmp_path.iterdir()) == []


def test_a_loaded_file_checks_what_it_is_given(knee, tmp_path) -> None:
    import onnx

    out, _meta, _agent, observations = knee
    policy = load_onnx_policy(out)
    with pytest.raises(UsageError, match=r"observation of shape \(49,\) does not fit"):
        policy.predict(observations[0][:49])
    with pytest.raises(UsageError, match="deterministic"):
        policy.predict(observations[0], deterministic=False)
    with pytest.raises(DataError, match="not found"):
        load_onnx_policy(tmp_path / "none.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(DataError, match=r"junk\.onnx is not a readable ONNX file"):
        load_onnx_policy(tmp_path / "junk.onnx")
    model = onnx.load(out)
    del model.metadata_props[:]
    onnx.save(model, tmp_path / "bare.onnx")
    with pytest.raises(OnnxExportError, match=r"bare\.onnx is not a rehabbot policy: its "
                                              r"metadata lacks 'format'"):
        load_onnx_policy(tmp_path / "bare.onnx")


# --------------------------------------------------------------------------- SB3 models


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_a_trained_sb3_run_exports_to_its_deterministic_predict(algo, tmp_path,
                                                               capsys) -> None:
    """A few hundred steps of SB3 training (PPO with VecNormalize statistics, which the file
    applies itself), saved as a run folder and exported by the command: onnxruntime's actions
    equal ``model.predict(obs, deterministic=True)`` on >= 1000 recorded observations."""
    sb3 = pytest.importorskip("stable_baselines3")
    pytest.importorskip("onnxruntime")
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from rehabbot.cli import main
    from rehabbot.rl.vecnormalize_io import save_vecnormalize

    env = gym.make(ENV_ID)
    run = tmp_path / "run"
    run.mkdir()
    if algo == "sac":
        model = sb3.SAC("MlpPolicy", env, seed=0, learning_starts=100, buffer_size=1000,
                        policy_kwargs={"net_arch": [32, 32]})
        normalize = None
    else:
        venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV_ID)]), norm_reward=False)
        venv.seed(0)
        model = sb3.PPO("MlpPolicy", venv, seed=0, n_steps=128, batch_size=64, n_epochs=1,
                        policy_kwargs={"net_arch": [32, 32]})
        normalize = venv
    model.learn(300)
    model.save(run / "model")
    if normalize is not None:
        save_vecnormalize(normalize, run / "vecnormalize.json")
    (run / "manifest.json").write_text(json.dumps({"env_id": ENV_ID, "algo": algo,
                                                   "seed": 0, "timesteps_done": 300}))
    out = tmp_path / f"{algo}.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0, capsys.readouterr().err
    policy = load_onnx_policy(out)
    assert policy.metadata["ops"][0] == ("normalize" if normalize else "dense")
    observations = record_observations(policy, ENV_ID, {}, episodes=1, seed=0,
                                       at_least=MIN_OBSERVATIONS)
    inputs = normalize.normalize_obs(observations) if normalize else observations
    expected, _ = model.predict(inputs, deterministic=True)
    assert np.max(np.abs(policy.predict(observations)[0] - expected)) <= TOLERANCE
    assert np.ptp(expected, axis=0).min() > 0
    if normalize is None:  # the same model as a loose zip, its env named by --env
        loose = tmp_path / "loose"
        loose.mkdir()
        (loose / "model.zip").write_bytes((run / "model.zip").read_bytes())
        assert main(["export", str(loose / "model.zip"), "--env", "rehab-knee-v2", "--out",
                     str(tmp_path / "loose.onnx")]) == 0
        meta = load_onnx_policy(tmp_path / "loose.onnx").metadata
        assert meta["weights_sha256"] == policy.metadata["weights_sha256"]
        assert meta["env_id"] == ENV_ID and meta["source"] == str(loose / "model.zip")
