"""``rehabbot sweep`` with ``backend: rsl_rl`` (:mod:`rehabbot.rl.sweep_config`,
:mod:`rehabbot.rl.sweep`): a sweep of rsl_rl's PPO on the batched env writes the run folders of
``rehabbot train --backend rsl_rl``. The file's checks and refusals, the state of a batched
run folder and Ray's resources need neither JAX nor Ray; the one slow test trains a trial of
8 worlds in-process (what a Ray worker does) and skips and resumes it."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

pytest.importorskip("yaml", reason="sweep files need PyYAML")

import yaml

from benchmarks.common.sweeps import KEY_FIELDS, row_key, sweep_keys
from rehabbot.common.errors import UsageError
from rehabbot.rl import batch_training as bt
from rehabbot.rl.algorithms import BackendUnavailableError
from rehabbot.rl.sweep import (
    SweepUsageError,
    check_batch_modules,
    check_local_resources,
    check_sweep,
    run_sweep,
    run_trial,
    trial_state,
)
from rehabbot.rl.sweep_config import (
    SweepConfigError,
    Trial,
    load_sweep_config,
    parse_sweep_config,
)

ROOT = Path(__file__).resolve().parents[1]
ENV = "rehab-reach-v2"
WORLDS = 8
ITERATION = 24 * WORLDS  # env steps of one PPO iteration (num_steps_per_env x worlds)
SMALL = {"actor_hidden_dims": [32, 32], "critic_hidden_dims": [32, 32], "num_mini_batches": 2}


def _config(tmp_path: Path, **overrides: object) -> dict:
    settings = tmp_path / "rsl-small.yml"
    settings.write_text(yaml.safe_dump({f"rehabbot/{ENV}": SMALL}))
    data = {"out": str(tmp_path / "out"), "envs": [ENV], "algos": ["ppo"], "seeds": [0],
            "timesteps": 2 * ITERATION, "backend": "rsl_rl", "n_envs": WORLDS,
            "hyperparams": str(settings), "checkpoint_freq": 0}
    data.update(overrides)
    return {key: value for key, value in data.items() if value is not None}


def _manifest(run_dir: Path) -> dict:
    return json.loads((run_dir / "manifest.json").read_text())


# --------------------------------------------------------------------------- the file


def test_a_batched_sweep_expands_into_the_run_folders_of_train_rsl_rl(tmp_path: Path) -> None:
    config = parse_sweep_config(_config(tmp_path, seeds=[0, 1],
                                        grid={"learning_rate": ["3e-4", 0.001]}))
    trials = check_sweep(config)
    assert [t.key for t in trials] == [
        f"learning_rate=3e-4/{ENV}/ppo/seed0", f"learning_rate=3e-4/{ENV}/ppo/seed1",
        f"learning_rate=0.001/{ENV}/ppo/seed0", f"learning_rate=0.001/{ENV}/ppo/seed1"]
    first = trials[0]
    assert first.batched and first.backend == "rsl_rl" and first.n_envs == WORLDS
    assert first.total_timesteps == 2 * ITERATION and first.checkpoint_freq == 0
    # The folder `rehabbot train --backend rsl_rl --out OUT/<variant>` writes.
    plan = bt.BatchRunPlan(ENV, seed=1, total_timesteps=1, out_dir=tmp_path / "out" /
                           "learning_rate=3e-4")
    assert trials[1].run_dir == plan.run_dir
    settings = first.build_rsl_settings()  # the file's entry for the id, the grid on top
    assert settings.learning_rate == pytest.approx(3e-4) and settings.num_mini_batches == 2
    assert settings.actor_hidden_dims == (32, 32)
    assert trials[2].build_rsl_settings().learning_rate == 0.001
    assert first.hyperparams["source"].endswith("rsl-small.yml [learning_rate=3e-4]")
    assert Trial.from_json(json.loads(json.dumps(first.to_json()))) == first
    with pytest.raises(UsageError, match="build_rsl_settings"):
        first.build_hyperparameters()


def test_a_batched_sweep_without_counts_takes_the_trainers_defaults(tmp_path: Path) -> None:
    (trial,) = parse_sweep_config(_config(tmp_path, n_envs=None, timesteps=None,
                                          hyperparams=None, checkpoint_freq=None)).trials()
    assert trial.n_envs == bt.DEFAULT_NUM_ENVS and trial.total_timesteps == bt.DEFAULT_TIMESTEPS
    assert trial.checkpoint_freq is None and trial.build_rsl_settings() == bt.RslPpoSettings()
    assert trial.hyperparams["source"] == "rsl_rl PPO defaults"


def test_one_sweep_may_mix_a_batched_ppo_with_cpu_algorithms(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3", reason="the sb3 backend trains the SAC trials")
    config = parse_sweep_config(_config(tmp_path, algos=["ppo", "sac"], seeds=[3],
                                        backend={"ppo": "rsl_rl", "sac": "sb3"},
                                        hyperparams={"ppo": str(tmp_path / "rsl-small.yml"),
                                                     "sac": "sac"},
                                        timesteps={"ppo": 2 * ITERATION, "sac": 500}))
    batched, sac = config.trials()
    assert (batched.algo, batched.backend, batched.n_envs) == ("ppo", "rsl_rl", WORLDS)
    assert (sac.algo, sac.backend, sac.total_timesteps) == ("sac", "sb3", 500)
    assert not sac.batched and sac.n_envs == WORLDS  # n_envs for every algorithm, as written


@pytest.mark.parametrize(("change", "message"), [
    ({"algos": ["sac"]}, "backend: rsl_rl trains ppo only, not 'sac'"),
    ({"algos": ["ppo", "td3"]}, "backend: rsl_rl trains ppo only, not 'td3'"),
    ({"eval_freq": 5000}, "eval_freq=5000 is not used by backend rsl_rl of ppo"),
    ({"eval_episodes": 3}, "eval_episodes=3 is not used by backend rsl_rl"),
    ({"demos": 20}, "demos=20 is not used by backend rsl_rl"),
    ({"demos": {"ppo": 20}}, "demos=20 is not used by backend rsl_rl"),
    ({"bc": True}, "bc=True is not used by backend rsl_rl"),
    ({"num_envs": 8}, "unknown key 'num_envs': write n_envs"),
    ({"backend": "rsl"}, "unknown backend 'rsl'; valid: auto, sb3, sbx, rsl_rl"),
    ({"grid": {"n_steps": [64]}}, "grid of ppo on rehab-reach-v2: unknown rsl_rl PPO settings "
                                  "['n_steps']"),
    ({"grid": {"ppo": {"learning_rate": [-1]}}}, "learning_rate=-1 must be a positive number"),
    ({"grid": {"schedule": ["cosine"]}}, "schedule='cosine' must be 'adaptive' or 'fixed'"),
    ({"hyperparams": "ppo"}, "hyperparams of ppo on rehab-reach-v2: cannot read rsl_rl PPO "
                             "settings file 'ppo'"),
    ({"n_envs": 0}, "n_envs must be an integer >= 1, got 0"),
    ({"resources_per_trial": {"gpu": -1}}, "resources_per_trial.gpu must be a number >= 0"),
])
def test_what_a_batched_sweep_cannot_do_is_refused_by_name(tmp_path: Path, change: dict,
                                                          message: str) -> None:
    with pytest.raises(SweepConfigError, match=re.escape(message)) as caught:
        parse_sweep_config(_config(tmp_path, **change), "s.yaml").trials()
    assert str(caught.value).startswith("s.yaml: ")


def test_a_settings_file_with_an_unknown_field_is_refused(tmp_path: Path) -> None:
    data = _config(tmp_path)
    Path(data["hyperparams"]).write_text("gama: 0.9\n")
    with pytest.raises(SweepConfigError, match=re.escape(
            "s.yaml: hyperparams of ppo on rehab-reach-v2: unknown rsl_rl PPO settings "
            "['gama']")):
        parse_sweep_config(data, "s.yaml").trials()


def test_what_the_batched_trainer_does_not_do_may_be_turned_off(tmp_path: Path) -> None:
    """0 and false ask for nothing, as ``rehabbot train --backend rsl_rl --eval-freq 0``."""
    config = parse_sweep_config(_config(tmp_path, eval_freq=0, demos=0, bc=False))
    assert len(config.trials()) == 1


def test_the_cli_refuses_a_bad_batched_sweep_with_exit_code_2(tmp_path, capsys) -> None:
    from rehabbot.cli import main

    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(_config(tmp_path, eval_freq=1000)))
    assert main(["sweep", str(path), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rehabbot: error: ") and "eval_freq=1000 is not used" in err
    path.write_text(yaml.safe_dump(_config(tmp_path)))
    assert main(["sweep", str(path), "--dry-run"]) == 0
    assert f"would train {ENV}/ppo/seed0 to {2 * ITERATION} steps" in capsys.readouterr().out


def test_the_shipped_batched_sweep_trains_the_published_runs() -> None:
    """sweeps/rsl-ppo-reach-v2.yaml trains the runs of docs/results/learning-batch.json: the
    same env, seeds and backend, and the steps those runs did (a run ends after the PPO
    iteration that reaches its step count: 163 x 256 worlds x 24 steps = 1 001 472)."""
    path = ROOT / "sweeps" / "rsl-ppo-reach-v2.yaml"
    config = load_sweep_config(path)
    trials = check_sweep(config)
    assert config.out.name == "results-batch" and config.out.parent.name == "runs"
    assert [(t.key, t.n_envs, t.total_timesteps) for t in trials] == [
        (f"{ENV}/ppo/seed{k}", 256, 1_000_000) for k in (0, 1, 2)]
    shipped = bt.RslPpoSettings.from_mapping(bt.read_settings(
        ROOT / "sweeps" / "results-batch" / "rsl-ppo-reach.yml", f"rehabbot/{ENV}"))
    assert {t.build_rsl_settings() for t in trials} == {shipped}
    page = json.loads((ROOT / "docs" / "results" / "learning-batch.json").read_text())
    table = next(t for t in page["tables"] if t["id"] == "runs")
    rows = [row_key(dict(zip(table["columns"], row, strict=True))) for row in table["rows"]]
    iteration = 256 * shipped.num_steps_per_env
    done = math.ceil(1_000_000 / iteration) * iteration
    steps = KEY_FIELDS.index("timesteps")
    assert sorted(rows) == sorted((*key[:steps], done, *key[steps + 1:])
                                  for key in sweep_keys(path))


# --------------------------------------------------------------------------- run folders


def _fake_run(run_dir: Path, **manifest: object) -> None:
    run_dir.mkdir(parents=True)
    values = {"env_id": f"rehabbot/{ENV}", "algo": "ppo", "seed": 0, "backend": "rsl_rl",
              "status": "finished", "timesteps_done": 2 * ITERATION}
    (run_dir / "manifest.json").write_text(json.dumps({**values, **manifest}))


def test_a_batched_run_folder_is_skipped_resumed_or_restarted(tmp_path: Path) -> None:
    (trial,) = parse_sweep_config(_config(tmp_path)).trials()
    run_dir = trial.run_dir
    assert trial_state(trial) == "new"
    _fake_run(run_dir)
    assert trial_state(trial) == "restart"  # finished, but no actor, no model, no checkpoint
    (run_dir / bt.FULL_MODEL_NAME).write_bytes(b"")
    assert trial_state(trial) == "resume"  # model.pt without policy.npz
    (run_dir / bt.POLICY_NAME).write_bytes(b"")
    assert trial_state(trial) == "complete"
    (longer,) = parse_sweep_config(_config(tmp_path, timesteps=3 * ITERATION)).trials()
    assert trial_state(longer) == "resume"  # from model.pt
    assert bt.resume_point(run_dir, _manifest(run_dir)) == (2 * ITERATION,
                                                            run_dir / bt.FULL_MODEL_NAME)

    running = tmp_path / "out" / ENV / "ppo" / "seed1"
    _fake_run(running, status="running", timesteps_done=ITERATION)
    (trial1,) = parse_sweep_config(_config(tmp_path, seeds=[1])).trials()
    assert trial_state(trial1) == "restart"
    bt.checkpoint_path(running, ITERATION).parent.mkdir()
    bt.checkpoint_path(running, ITERATION).write_bytes(b"")
    assert trial_state(trial1) == "resume"

    # A run of another backend in the folder is left to train_batched, which refuses it by
    # name; the sweep never starts it over.
    other = tmp_path / "out" / ENV / "ppo" / "seed2"
    _fake_run(other, backend="sbx")
    (trial2,) = parse_sweep_config(_config(tmp_path, seeds=[2])).trials()
    assert trial_state(trial2) == "resume"


def test_resources_a_local_ray_cannot_give_are_refused() -> None:
    check_local_resources({"cpu": 2, "gpu": 1}, {"CPU": 4.0, "GPU": 1.0, "memory": 1e9})
    with pytest.raises(SweepUsageError, match=r"gpu: 1 per trial, but the local Ray has 0; "
                                              r"Ray finds no GPU here"):
        check_local_resources({"cpu": 1, "gpu": 1}, {"CPU": 4.0, "memory": 1e9})
    with pytest.raises(SweepUsageError, match=r"gpu: 0.5 per trial, but the local Ray has 0"):
        check_local_resources({"gpu": 0.5}, {"CPU": 4.0, "GPU": 0.0})
    with pytest.raises(SweepUsageError, match=r"accelerator: 1 per trial, but the local Ray "
                                              r"has 0$"):
        check_local_resources({"accelerator": 1}, {"CPU": 4.0})


def test_a_local_batched_sweep_without_its_modules_is_refused_before_ray(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bt, "missing_modules", lambda: ["warp", "rsl_rl"])
    config = parse_sweep_config(_config(tmp_path))
    with pytest.raises(BackendUnavailableError, match=re.escape(
            'backend rsl_rl needs warp, rsl_rl, which are not installed (pip install '
            '"rehabbot[gpu]")')):
        run_sweep(config, cpus=1, announce=lambda text: None)
    assert not (tmp_path / "out" / "_ray").exists()
    # A dry run starts nothing; a cluster's nodes have their own packages.
    assert run_sweep(config, dry_run=True, announce=lambda text: None).records
    check_batch_modules([])


def test_resources_per_trial_take_gpu_in_either_case(tmp_path: Path) -> None:
    config = parse_sweep_config(_config(tmp_path, resources_per_trial={"CPU": 2, "GPU": 1}))
    assert config.resources_per_trial == {"cpu": 2, "gpu": 1}


# --------------------------------------------------------------------------- training


@pytest.mark.slow
def test_a_batched_trial_trains_then_skips_then_resumes(tmp_path: Path) -> None:
    """What a Ray worker does, in-process: two PPO iterations of 8 worlds on Warp's CPU
    device; the sweep then skips the finished run without starting Ray; more steps continue
    it from its model.pt."""
    pytest.importorskip("jax")
    pytest.importorskip("warp")
    pytest.importorskip("torch")
    pytest.importorskip("rsl_rl")
    config = parse_sweep_config(_config(tmp_path), "s.yaml")
    (trial,) = check_sweep(config)
    record = run_trial(trial.to_json(), ["rehabbot", "sweep", "s.yaml"])
    assert record["status"] == "finished" and record["action"] == "trained", record
    run_dir = tmp_path / "out" / ENV / "ppo" / "seed0"
    manifest = _manifest(run_dir)
    assert manifest["backend"] == "rsl_rl" and manifest["status"] == "finished"
    assert manifest["timesteps_done"] == 2 * ITERATION and manifest["n_envs"] == WORLDS
    assert manifest["hyperparameters"]["actor_hidden_dims"] == [32, 32]
    assert manifest["command"] == ["rehabbot", "sweep", "s.yaml"]
    assert (run_dir / "policy.npz").is_file() and (run_dir / "model.pt").is_file()

    lines: list[str] = []
    result = run_sweep(config, announce=lines.append)  # nothing to run: Ray is not started
    assert "1 trials in" in lines[0] and "1 complete, 0 to resume, 0 to start" in lines[0]
    assert [(r["status"], r["action"]) for r in result.records] == [("finished", "skipped")]
    assert _manifest(run_dir) == manifest
    assert not (tmp_path / "out" / "_ray").exists()

    (longer,) = parse_sweep_config(_config(tmp_path, timesteps=3 * ITERATION)).trials()
    record = run_trial(longer.to_json())
    assert record["status"] == "finished" and record["action"] == "resumed", record
    manifest = _manifest(run_dir)
    assert manifest["timesteps_done"] == 3 * ITERATION and manifest["iterations_done"] == 3
    assert manifest["resumed_from"] == "model.pt"
    assert [s["start_timesteps"] for s in manifest["segments"]] == [0, 2 * ITERATION]
