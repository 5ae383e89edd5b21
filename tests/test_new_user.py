"""What a new user trips over (issue "One house with clear rooms", part 3): each test is one
thing that failed on a fresh clone before, run the way a user runs it."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import weakref
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rehabbot
from rehabbot.cli import main
from rehabbot.envs.registration import (
    CONDITION_VARIANTS,
    ENV_SPECS,
    MYO_VARIANTS,
    POPULATION_VARIANTS,
    RANDOMIZED_VARIANTS,
)

ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
SHORT = {"max_episode_steps": 60}


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
    """A tiny PPO run of `rehabbot train` (weight level 0, the default profile)."""
    pytest.importorskip("stable_baselines3")
    from rehabbot.rl.training import train_run

    out = tmp_path_factory.mktemp("runs")
    return train_run(ENV, "ppo", 0, 128, out, hyperparams={
        "n_steps": 64, "batch_size": 32, "n_epochs": 1,
        "policy_kwargs": "dict(net_arch=[8, 8])"},
        env_kwargs={**SHORT, "weight_level": 0}, eval_freq=0, checkpoint_freq=0,
        progress_bar=False, backend="sb3")


# -- evaluate: the README's command, every argument checked first -------------------------
def test_evaluate_takes_the_env_from_the_model_for_expert_and_random(trained_run, tmp_path,
                                                                     capsys) -> None:
    out = tmp_path / "compare"
    code = main(["evaluate", str(trained_run / "model.zip"), "expert", "random",
                 "--episodes", "1", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    reports = {p.parent.name: json.loads(p.read_text()) for p in out.glob("*/evaluation.json")}
    assert set(reports) == {"ppo-seed0", "expert", "random"}
    assert {r["env_id"] for r in reports.values()} == {FULL_ID}
    assert all(r["env_kwargs"] == {**SHORT, "weight_level": 0} for r in reports.values())
    assert (out / "comparison.md").is_file()


def test_a_bad_policy_fails_before_anything_is_written(trained_run, tmp_path, capsys) -> None:
    out = tmp_path / "compare"
    code = main(["evaluate", str(trained_run / "model.zip"), "expert",
                 str(tmp_path / "missing.zip"), "--episodes", "1", "--out", str(out)])
    assert code == 1
    assert "missing.zip" in capsys.readouterr().err
    assert not out.exists() or not list(out.rglob("*.json"))
    assert main(["evaluate", "expert", "random", "--episodes", "1"]) == 2
    assert "need(s) --env ENV" in capsys.readouterr().err


@pytest.mark.slow
def test_the_readme_session_plots_the_comparison_it_evaluated(trained_run, tmp_path,
                                                             monkeypatch, capsys) -> None:
    """README: `rehabbot evaluate <run>/model.zip expert random`, then `rehabbot plot
    runs/<env>`: the plot draws that comparison (and Fig. 10) and evaluates nothing again;
    an evaluation of other policies before it does not block it."""
    pytest.importorskip("matplotlib")
    import shutil

    monkeypatch.chdir(tmp_path)
    run = Path("runs") / ENV / "ppo" / "seed0"
    shutil.copytree(trained_run, run, ignore=shutil.ignore_patterns("evaluation"))
    assert main(["evaluate", "expert", "aan", "--env", ENV, "--episodes", "1"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(run / "model.zip"), "expert", "random", "--episodes",
                 "1"]) == 0
    out = capsys.readouterr().out
    comparison = Path("runs") / ENV / "evaluation" / "ppo-seed0+expert+random"
    assert out.rstrip().endswith(f"rehabbot plot {comparison}")
    assert (comparison / "comparison.md").is_file()
    assert (Path("runs") / "evaluation" / ENV / "expert+aan" / "comparison.md").is_file()
    assert main(["plot", f"runs/{ENV}", "--formats", "png", "--dpi", "50"]) == 0
    printed = capsys.readouterr().out
    assert "has no evaluated episode" not in printed  # nothing evaluated again
    assert not (run / "evaluation").exists()
    names = {Path(line).name for line in printed.split()}
    assert f"fig10_overlay_{ENV}.png" in names and "fig4_learning_curves.png" in names
    for label in ("ppo-seed0", "expert", "random"):
        assert f"fig8_cuff_force_{label}_{ENV}.png" in names


# -- one id, one pair of spaces -------------------------------------------------------------
@pytest.mark.parametrize("env_id", [env_id if env_id.endswith("reach-v0") else
                                    pytest.param(env_id, marks=pytest.mark.slow)
                                    for env_id in ENV_SPECS
                                    # (the variants share their base id's spaces: tested in
                                    # test_conditions.py, test_population.py and, for MyoSuite's
                                    # legs, which seat one profile, test_myo_patient.py;
                                    # the randomised ids in test_randomization.py)
                                    if env_id not in CONDITION_VARIANTS
                                    and env_id not in POPULATION_VARIANTS
                                    and env_id not in RANDOMIZED_VARIANTS
                                    and env_id not in MYO_VARIANTS])
def test_spaces_do_not_depend_on_the_patient_or_the_weight_level(env_id: str) -> None:
    for mode in ("joint_delta", "joint_position"):
        spaces = set()
        for kwargs in ({}, {"weight_level": 4},
                       {"profile": {"height_m": 1.6, "mass_kg": 55.0, "sex": "female"}},
                       {"profile": {"height_m": 1.9, "mass_kg": 95.0}, "weight_level": 2,
                        "exercise": 1}):
            env = gym.make(env_id, control_mode=mode, **kwargs)
            spaces.add((repr(env.observation_space), repr(env.action_space),
                        env.observation_space.low.tobytes(),
                        env.observation_space.high.tobytes(), env.action_space.low.tobytes()))
            obs, _ = env.reset(seed=0)
            assert env.observation_space.contains(obs)
            env.close()
        assert len(spaces) == 1, (env_id, mode)


@pytest.mark.slow
def test_a_model_runs_on_another_patient_and_weight_level(trained_run, tmp_path,
                                                          capsys) -> None:
    kwargs = {"weight_level": 4, "profile": {"height_m": 1.62, "mass_kg": 58.0,
                                             "sex": "female"}}
    out = tmp_path / "other"
    code = main(["evaluate", str(trained_run / "model.zip"), "--episodes", "1",
                 "--env-kwargs", json.dumps(kwargs), "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / "ppo-seed0" / "evaluation.json").read_text())
    assert report["env_kwargs"]["weight_level"] == 4  # the override of the run's level 0
    assert report["per_episode"][0]["weight_level"] == 4


# -- output folders, videos, checkpoints ----------------------------------------------------
@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs /proc")
def test_an_unusable_output_folder_is_one_line_and_exit_1(capsys) -> None:
    code = main(["train", ENV, "--algo", "ppo", "--out", "/proc/rehabbot-runs",
                 "--timesteps", "64", "--hyperparams", "sb3-defaults/ppo"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("rehabbot: error: cannot write to output folder '/proc/rehabbot-runs'")
    assert "Traceback" not in err and err.count("\n") == 1


@pytest.mark.slow
def test_videos_get_the_usual_permissions_and_frames_are_streamed(tmp_path, monkeypatch,
                                                                    capsys) -> None:
    pytest.importorskip("imageio_ffmpeg")
    import rehabbot.analysis.video as video

    alive: list[weakref.ref] = []
    most_alive = [0]
    real_append = video._FrameWriter.append

    def append(self, frame):  # a frame must be gone once the writer has it
        alive.append(weakref.ref(frame))
        most_alive[0] = max(most_alive[0], sum(ref() is not None for ref in alive))
        real_append(self, frame)

    monkeypatch.setattr(video._FrameWriter, "append", append)
    old_umask = os.umask(0o022)
    try:
        out = tmp_path / "expert.mp4"
        assert main(["render", "expert", "--env", ENV, "--out", str(out), "--width", "64",
                     "--height", "48", "--frame-every", "10"]) == 0
    finally:
        os.umask(old_umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert len(alive) > 20 and most_alive[0] <= 2  # not a list of every frame


def test_a_short_sac_run_writes_a_small_replay_buffer(tmp_path) -> None:
    pytest.importorskip("stable_baselines3")
    from rehabbot.rl.training import train_run

    run_dir = train_run(ENV, "sac", 0, 400, tmp_path, env_kwargs=SHORT, eval_freq=0,
                        checkpoint_freq=0, progress_bar=False, backend="sb3",
                        hyperparams={"learning_starts": 300, "batch_size": 16,
                                     "policy_kwargs": "dict(net_arch=[8, 8])"})
    buffer = run_dir / "checkpoints" / "rl_model_replay_buffer_400_steps.npz"
    # SB3's default buffer holds 1e6 transitions (a 220 MB pickle); only 400 are saved.
    assert 0 < buffer.stat().st_size < 200_000
    with np.load(buffer) as saved:
        assert saved["observations"].shape[0] == int(saved["pos"]) <= 400


@pytest.mark.slow
def test_plot_says_when_it_evaluates_a_run(trained_run, tmp_path, capsys) -> None:
    pytest.importorskip("matplotlib")
    assert main(["plot", str(trained_run), "--out", str(tmp_path / "figs"),
                 "--formats", "png"]) == 0
    out = capsys.readouterr().out
    assert "has no evaluated episode: evaluating its model.zip" in out
    assert (trained_run / "evaluation" / "ppo-seed0" / "trace.npz").is_file()


# -- Gymnasium conventions -------------------------------------------------------------------
def test_env_dt_and_version_and_citation(capsys) -> None:
    env = gym.make(FULL_ID)
    assert env.unwrapped.dt == pytest.approx(0.02)
    assert env.get_wrapper_attr("dt") == pytest.approx(0.02)
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"rehabbot {rehabbot.__version__}"
    citation = (Path(__file__).resolve().parents[1] / "CITATION.cff").read_text()
    assert "cff-version:" in citation and f"version: {rehabbot.__version__}" in citation


def test_python_dash_m_rehabbot_is_the_command() -> None:
    result = subprocess.run([sys.executable, "-m", "rehabbot", "--version"],
                            capture_output=True, text=True, timeout=600, check=True)
    assert result.stdout.strip() == f"rehabbot {rehabbot.__version__}"


def test_training_subprocess_envs_start_with_spawn() -> None:
    from rehabbot.rl import training

    assert training.SUBPROC_START_METHOD == "spawn"
