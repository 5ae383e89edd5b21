"""``rehabbot sweep`` (:mod:`rehabbot.rl.sweep`, :mod:`rehabbot.rl.sweep_config`,
:mod:`rehabbot.cli.sweep`): the sweep file's checks, the run folders of its trials, resuming
and skipping, and the readers of a sweep's folder (results table, plot). Only the last test
starts Ray (a local one of 2 CPUs, 2 trials of 200 steps); the others call a trial in-process.
"""

from __future__ import annotations

import json
import re
import signal
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3", reason='sweeps train with "rehabbot[train]"')
pytest.importorskip("yaml", reason="sweep files need PyYAML")

import yaml

from benchmarks.results import results_table
from rehabbot.cli import main
from rehabbot.rl import sweep as sweep_module
from rehabbot.rl.sweep import check_sweep, run_sweep, run_trial, trial_state
from rehabbot.rl.sweep_config import (
    SweepConfigError,
    load_sweep_config,
    parse_sweep_config,
    variant_name,
    variants,
)

ROOT = Path(__file__).resolve().parents[1]
ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
# Tiny networks, no gradient step before step 40 (a run must update its model:
# rehabbot.rl.planning.check_run_updates): a 200-step run takes about a second (on
# Stable-Baselines3: SBX compiles its networks first, which takes longer).
SMALL_SAC = {"learning_starts": 40, "buffer_size": 2000, "batch_size": 32,
             "policy_kwargs": "dict(net_arch=[16, 16])"}


def _config(tmp_path: Path, **overrides) -> dict:
    hp_file = tmp_path / "sac-small.yml"
    hp_file.write_text(yaml.safe_dump({"default": SMALL_SAC}))
    data = {"out": str(tmp_path / "out"), "envs": [ENV], "algos": ["sac"], "seeds": [0],
            "timesteps": 100, "hyperparams": {"sac": str(hp_file)}, "eval_freq": 100,
            "eval_episodes": 1, "checkpoint_freq": 100,
            "env_kwargs": {"max_episode_steps": 50}, "backend": "sb3"}
    data.update(overrides)
    return {key: value for key, value in data.items() if value is not None}


def _write(tmp_path: Path, data: dict, name: str = "sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _manifest(run_dir: Path) -> dict:
    return json.loads((run_dir / "manifest.json").read_text())


# --------------------------------------------------------------------------- the file


def test_a_sweep_file_expands_into_trials_and_run_folders(tmp_path: Path) -> None:
    config = parse_sweep_config(_config(
        tmp_path, envs=["rehab-reach-v2", "rehabbot/rehab-hip-v2"], algos=["sac", "td3"],
        seeds=[0, 1],
        timesteps={"sac": 300, "td3": 400}, hyperparams={"sac": "sac", "td3": "td3"},
        grid={"sac": {"learning_rate": [0.001, "3e-4"]}}))
    trials = config.trials()
    assert len(trials) == 2 * (2 + 1) * 2  # envs x (SAC variants + TD3) x seeds
    out = tmp_path / "out"
    keys = [t.key for t in trials]
    assert keys[:4] == ["learning_rate=0.001/rehab-reach-v2/sac/seed0",
                        "learning_rate=0.001/rehab-reach-v2/sac/seed1",
                        "learning_rate=3e-4/rehab-reach-v2/sac/seed0",
                        "learning_rate=3e-4/rehab-reach-v2/sac/seed1"]
    assert "rehab-hip-v2/td3/seed1" in keys
    for trial in trials:
        assert trial.run_dir == out / trial.key
    sac = trials[0]
    assert sac.total_timesteps == 300 and trials[5].total_timesteps == 400
    assert sac.hyperparams["source"] == "sac [learning_rate=0.001]"
    hp = sac.build_hyperparameters()
    assert hp.kwargs["learning_rate"] == 0.001 and hp.kwargs["n_steps"] == 10  # file + grid
    assert trials[2].build_hyperparameters().kwargs["learning_rate"] == pytest.approx(3e-4)
    assert trials[4].variant is None and trials[4].hyperparams["source"] == "td3"


def test_variant_names_are_folder_names() -> None:
    assert variant_name({"learning_rate": 0.001, "batch_size": 128}) == \
        "learning_rate=0.001,batch_size=128"
    assert variant_name({"policy_kwargs": {"net_arch": [64, 64]}}) == \
        "policy_kwargs=__net_arch___64,64__"
    long = variant_name({"policy_kwargs": "dict(net_arch=[" + "64, " * 40 + "64])"})
    assert len(long) <= 80 and "/" not in long
    # Two grid values that read the same as a folder name get two folders.
    (first, _), (second, _) = variants({"gamma": [0.9, "0.9"]})
    assert first == "gamma=0.9" and second.startswith("gamma=0.9-") and len(second) == 18


@pytest.mark.slow
def test_the_shipped_sweep_files_load() -> None:
    base = {"rehabbot/rehab-reach-v2", "rehabbot/rehab-reach-l-v2", "rehabbot/rehab-hip-v2",
            "rehabbot/rehab-knee-v2"}
    example = load_sweep_config(ROOT / "sweeps" / "example.yaml")
    assert len(example.trials()) == 12
    # The published -v2 runs (docs/results/learning-v2.md), one grid per block of seeds;
    # tests/test_results_pages.py compares them with the table run by run.
    blocks = sorted((ROOT / "sweeps" / "results-v2").glob("*.yaml"))
    trials = [t for path in blocks for t in load_sweep_config(path).trials()]
    assert len(trials) == 29 and base < {t.env_id for t in trials}
    steps = {(t.algo, bool(t.bc)): t.total_timesteps for t in trials}
    assert steps == {("sac", False): 100_000, ("td3", False): 100_000,
                     ("ppo", False): 1_000_000, ("ppo", True): 300_000}
    assert {t.backend for t in trials} == {"sbx"}
    # Every grid trains -v2 ids, with the libraries' MlpPolicy (the shipped settings) or, on
    # the batched env, rsl_rl's MLPs (tests/test_sweep_batch.py checks those).
    shipped = sorted((ROOT / "sweeps").rglob("*.yaml"))
    for path in shipped:
        config = load_sweep_config(path)
        check_sweep(config)  # the settings load for every id, the env kwargs fit
        assert {t.env_id.rsplit("-", 1)[1] for t in config.trials()} == {"v2"}, path.name
        cpu = [t for t in config.trials() if not t.batched]
        assert {t.hyperparams["given"].get("policy") for t in cpu} == \
            ({"MlpPolicy"} if cpu else set()), path.name
    assert [path.name for path in shipped
            if all(t.batched for t in load_sweep_config(path).trials())] == \
        ["rsl-ppo-knee-population-v2.yaml", "rsl-ppo-reach-population-v2.yaml",
         "rsl-ppo-reach-v2.yaml"]
    ppo = load_sweep_config(ROOT / "sweeps" / "ppo-v2.yaml").trials()
    assert len(ppo) == 12 and {(t.algo, t.backend, t.demos, t.bc, t.total_timesteps)
                               for t in ppo} == {("ppo", "sbx", 40, True, 300_000)}
    for name, algo in (("sac-v2", "sac"), ("td3-v2", "td3")):
        runs = load_sweep_config(ROOT / "sweeps" / f"{name}.yaml").trials()
        assert len(runs) == 12 and {t.env_id for t in runs} == base
        assert {(t.algo, t.backend, t.demos, t.total_timesteps) for t in runs} == \
            {(algo, "sbx", 20, 100_000)} and {t.seed for t in runs} == {0, 1, 2}
    fr3 = load_sweep_config(ROOT / "sweeps" / "sac-fr3-v2.yaml").trials()
    assert len(fr3) == 12 and {t.total_timesteps for t in fr3} == {100_000}
    assert all(t.env_kwargs == {"robot": "fr3"} for t in fr3)
    bilateral = load_sweep_config(ROOT / "sweeps" / "sac-bilateral-v2.yaml").trials()
    assert {(t.env_id, t.algo, t.total_timesteps) for t in bilateral} == \
        {("rehabbot/rehab-bilateral-v2", "sac", 300_000)} and len(bilateral) == 3
    for name, env_id, env_kwargs in (("ppo-bc-bilateral-v2", "rehabbot/rehab-bilateral-v2", None),
                                     ("ppo-bc-fr3-hip-v2", "rehabbot/rehab-hip-v2",
                                      {"robot": "fr3"})):
        trials = load_sweep_config(ROOT / "sweeps" / f"{name}.yaml").trials()
        assert {(t.env_id, t.algo, t.bc, t.demos, t.total_timesteps) for t in trials} == \
            {(env_id, "ppo", True, 20, 300_000)} and len(trials) == 3
        assert all(t.env_kwargs == env_kwargs for t in trials)
    conditions = load_sweep_config(ROOT / "sweeps" / "sac-conditions-v2.yaml").trials()
    assert len(conditions) == 7 and all("-v2" in t.env_id for t in conditions)


def test_a_sweep_of_a_paper_observation_id_with_the_shipped_settings_is_refused(
        tmp_path: Path) -> None:
    """The shipped settings have no entries for the -v0/-v1 ids; the sweep says which id to
    train instead before anything starts."""
    config = parse_sweep_config(_config(tmp_path, envs=["rehab-knee-v1"],
                                        hyperparams={"sac": "sac"}))
    with pytest.raises(SweepConfigError, match=r"no entry for rehabbot/rehab-knee-v1: .* train "
                                               r"rehabbot/rehab-knee-v2"):
        check_sweep(config)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("change", "message"), [
    ({"learning_rate": 0.1}, "unknown key 'learning_rate'"),
    ({"envs": ["rehab-elbow-v0"]}, "unknown env id 'rehab-elbow-v0'"),
    ({"algos": ["dqn"]}, "unknown algorithm 'dqn'"),
    ({"seeds": [0, -1]}, "seeds must be an integer >= 0, got -1"),
    ({"seeds": None}, "missing key 'seeds'"),
    ({"timesteps": {"ppo": 100}}, "timesteps names algorithm 'ppo', which is not in algos"),
    ({"timesteps": 0}, "timesteps must be an integer >= 1, got 0"),
    ({"grid": {"learnin_rate": [0.1]}}, "unknown hyperparameter 'learnin_rate' for SAC"),
    ({"grid": {"learning_rate": 0.1}}, "grid.learning_rate must be a non-empty list"),
    ({"grid": {"sac": {"gamma": [0.9]}, "gamma": [0.9]}}, "grid mixes algorithms"),
    ({"hyperparams": {"sac": "no-such-settings"}}, "'no-such-settings' not found"),
    ({"resources_per_trial": {"cpu": -1}}, "resources_per_trial.cpu must be a number >= 0"),
    ({"backend": "tpu"}, "unknown backend 'tpu'"),
    ({"bc": "yes"}, "bc must be true or false, got 'yes'"),
])
def test_bad_sweep_files_are_refused_naming_the_value(tmp_path: Path, change: dict,
                                                      message: str) -> None:
    data = _config(tmp_path)
    for key, value in change.items():
        if value is None:
            data.pop(key)
        else:
            data[key] = value
    with pytest.raises(SweepConfigError, match=re.escape(message)):
        parse_sweep_config(data, "s.yaml").trials()


def test_bad_env_kwargs_and_demos_are_refused_before_anything_runs(tmp_path):
    config = parse_sweep_config(_config(tmp_path, env_kwargs={"weight_level": 9}))
    with pytest.raises(SweepConfigError, match=r"env_kwargs: .*weight_level=9"):
        check_sweep(config)
    with pytest.raises(SweepConfigError, match=r"ppo: .*needs --bc"):  # train_run's own rules
        check_sweep(parse_sweep_config(_config(tmp_path, algos=["ppo"], hyperparams=None,
                                               demos=3)))
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("change", "message"), [
    ({"envs": ["rehab-elbow-v0"]}, "unknown env id 'rehab-elbow-v0'"),
    ({"algos": ["sac", "a2c"]}, "unknown algorithm 'a2c'"),
    ({"seedz": [0]}, "unknown key 'seedz'"),
])
def test_the_cli_gives_one_line_and_exit_code_2(tmp_path, capsys, change, message) -> None:
    path = _write(tmp_path, {**_config(tmp_path), **change})
    assert main(["sweep", str(path), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rehabbot: error: ") and message in err and "\n" not in err


def test_the_cli_refuses_resume_without_a_sweep_and_bad_files(tmp_path, capsys) -> None:
    path = _write(tmp_path, _config(tmp_path))
    assert main(["sweep", str(path), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    assert main(["sweep", str(tmp_path / "missing.yaml")]) == 2
    assert "cannot read sweep file" in capsys.readouterr().err
    (tmp_path / "broken.yaml").write_text("envs: [a, b\n")
    assert main(["sweep", str(tmp_path / "broken.yaml")]) == 2
    assert "is not valid YAML" in capsys.readouterr().err


def test_run_sweep_refuses_more_cpus_per_trial_than_the_local_ray_has(tmp_path) -> None:
    config = parse_sweep_config(_config(tmp_path, resources_per_trial={"cpu": 4}))
    with pytest.raises(sweep_module.SweepUsageError, match=r"4 CPUs per trial.*raise --cpus"):
        run_sweep(config, cpus=2, announce=lambda text: None)


# --------------------------------------------------------------------------- trials


def test_a_trial_takes_n_envs_from_its_settings_file(tmp_path: Path) -> None:
    """Without n_envs in the sweep file, a trial trains with the settings file's n_envs (as
    `rehabbot train` does), not with one env."""
    data = _config(tmp_path, eval_freq=0, checkpoint_freq=0, timesteps=50)
    (tmp_path / "sac-small.yml").write_text(yaml.safe_dump({"default": {**SMALL_SAC,
                                                                        "n_envs": 2}}))
    (trial,) = parse_sweep_config(data).trials()
    assert trial.n_envs is None
    assert run_trial(trial.to_json())["status"] == "finished"
    assert _manifest(trial.run_dir)["n_envs"] == 2


def test_a_trial_trains_then_skips_then_resumes_to_more_steps(tmp_path: Path) -> None:
    """What a Ray worker does, in-process: train, skip a complete run, continue one."""
    small = {"grid": {"gamma": [0.95]}, "eval_freq": 0, "checkpoint_freq": 50, "timesteps": 50}
    (trial,) = parse_sweep_config(_config(tmp_path, **small)).trials()
    run_dir = trial.run_dir
    assert run_dir == tmp_path / "out" / "gamma=0.95" / ENV / "sac" / "seed0"
    assert trial_state(trial) == "new"
    record = run_trial(trial.to_json(), ["rehabbot", "sweep", "s.yaml"])
    assert record["status"] == "finished" and record["action"] == "trained", record
    manifest = _manifest(run_dir)
    assert manifest["status"] == "finished" and manifest["timesteps_done"] == 50
    assert manifest["command"] == ["rehabbot", "sweep", "s.yaml"]
    assert manifest["hyperparameters"]["source"].endswith("sac-small.yml [gamma=0.95]")
    assert manifest["hyperparameters"]["kwargs"]["gamma"] == 0.95
    assert trial_state(trial) == "complete"
    again = run_trial(trial.to_json())
    assert again["action"] == "skipped" and _manifest(run_dir) == manifest

    (longer,) = parse_sweep_config(_config(tmp_path, **{**small, "timesteps": 100})).trials()
    assert trial_state(longer) == "resume"
    record = run_trial(longer.to_json())
    assert record["status"] == "finished" and record["action"] == "resumed", record
    manifest = _manifest(run_dir)
    assert manifest["timesteps_done"] == 100 and len(manifest["segments"]) == 2

    # The sweep's folder is an ordinary folder of runs for the results table and the plots.
    assert results_table.find_runs([tmp_path / "out"]) == [run_dir]
    learning_curves = pytest.importorskip("rehabbot.analysis.learning_curves")
    assert [run.path for run in learning_curves.load_runs([tmp_path / "out"])] == [run_dir]


def test_a_failing_trial_is_reported_not_raised(tmp_path: Path) -> None:
    # The sweep's checks refuse every bad value they can before anything runs...
    with pytest.raises(SweepConfigError, match="target_entropy='bogus'"):
        parse_sweep_config(_config(tmp_path, grid={"target_entropy": ["bogus"]})).trials()
    # ...but a policy_kwargs key is known only to the policy's constructor: this trial
    # fails at run time, when train_run builds the model.
    config = parse_sweep_config(_config(
        tmp_path, grid={"policy_kwargs": ["dict(net_arch=[16, 16], bogus_option=1)"]}))
    (trial,) = config.trials()
    record = run_trial(trial.to_json())
    assert record["status"] == "failed" and record["action"] == "trained", record
    assert "bogus_option" in record["error"] and "\n" not in record["error"]
    assert not trial.run_dir.exists()  # train_run leaves nothing behind for a new run


# --------------------------------------------------------------------------- on Ray


@pytest.mark.slow
def test_a_sweep_on_a_local_ray_writes_run_folders_and_resumes(tmp_path, capsys,
                                                              monkeypatch) -> None:
    pytest.importorskip("ray.tune", reason='sweeps run on Ray Tune ("rehabbot[sweep]")')
    for name, value in sweep_module.RAY_ENV_DEFAULTS.items():
        monkeypatch.setenv(name, value)  # restored after the test
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    path = _write(tmp_path, _config(tmp_path, seeds=[0, 1], timesteps=200))
    out = tmp_path / "out"

    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    assert main(["sweep", str(path), "--cpus", "2"]) == 0
    # Ray's own SIGINT and SIGTERM handlers do not outlive the sweep (they would swallow a
    # later signal).
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers
    printed = capsys.readouterr().out
    run_dirs = [out / ENV / "sac" / f"seed{seed}" for seed in (0, 1)]
    manifests = [_manifest(run_dir) for run_dir in run_dirs]
    for run_dir, manifest in zip(run_dirs, manifests, strict=True):
        assert manifest["status"] == "finished" and manifest["timesteps_done"] == 200
        assert manifest["env_id"] == FULL_ID and (run_dir / "model.zip").is_file()
        assert f"{ENV}/sac/seed{manifest['seed']}: finished (trained)" in printed
    sweep = json.loads((out / "sweep.json").read_text())
    assert [(t["run_dir"], t["status"], t["action"]) for t in sweep["trials"]] == [
        (f"{ENV}/sac/seed0", "finished", "trained"), (f"{ENV}/sac/seed1", "finished", "trained")]
    experiments = list((out / "_ray").iterdir())
    assert len(experiments) == 1 and experiments[0].name == sweep["ray"]["experiment"]
    assert not (tmp_path / "home" / "ray_results").exists()

    # Again: nothing is retrained, Ray is not even started.
    assert main(["sweep", str(path), "--cpus", "2", "--resume"]) == 0
    printed = capsys.readouterr().out
    assert "2 complete, 0 to resume, 0 to start" in printed
    assert [_manifest(run_dir) for run_dir in run_dirs] == manifests
    sweep = json.loads((out / "sweep.json").read_text())
    assert {t["action"] for t in sweep["trials"]} == {"skipped"}
    assert len(list((out / "_ray").iterdir())) == 1

    rows = results_table.table_rows([out], episodes=1, seed=1000)
    sac = [row for row in rows if row["policy"].startswith("SAC (")]
    assert len(sac) == 1 and sac[0]["seeds"] == [0, 1] and sac[0]["steps"] == [200]

    pytest.importorskip("matplotlib", reason='figures need "rehabbot[plot]"')
    figures = tmp_path / "figures"
    assert main(["plot", str(out), "--no-evaluate", "--formats", "png", "--out",
                 str(figures)]) == 0
    assert (figures / "fig4_learning_curves.png").is_file()
