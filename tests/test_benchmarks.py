"""The benchmark scripts run and report what they claim: here that their tables are produced
and consistent, on tiny runs. The published figures are written by the scripts themselves to
``docs/results/`` (a JSON document and its Markdown page, benchmarks/common/documents.py);
tests/test_results_pages.py checks those pages against their JSON and their sweep files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from benchmarks.performance import step_throughput
from benchmarks.probes import bilateral_sync, expert_agreement
from benchmarks.results import profile_envelope, robot_placement
from rehabbot.envs.rehab_env import RehabEnv

ENV = "rehabbot/rehab-reach-v0"
ROOT = Path(__file__).resolve().parents[1]


def squeezed(text: str) -> str:
    """Markdown tables with their padding taken out: runs of spaces as one."""
    return re.sub(" +", " ", text)


def test_step_throughput_measures_the_env_as_users_make_it(capsys) -> None:
    assert step_throughput.main(["--steps", "30", "--rounds", "3", "--warmup", "5",
                                 "--ids", "rehab-reach-v0"]) == 0
    out = capsys.readouterr().out
    # gym.make's own wrappers: the registration's TimeLimit only.
    assert "wrappers: TimeLimit;" in out
    row = next(line for line in out.splitlines() if line.startswith(f"| {ENV} "))
    cells = [c.strip() for c in row.strip("|").split("|")]
    env_rate, physics_rate = float(cells[1]), float(cells[2])
    share = float(re.match(r"([0-9.]+)%", cells[3]).group(1)) / 100
    assert env_rate > 0 and physics_rate > 0
    assert 0.0 < share <= 1.5  # physics time / env time, noisy at 30 steps


def test_step_throughput_refuses_unknown_ids(capsys) -> None:
    assert step_throughput.main(["--ids", "rehab-elbow-v9"]) == 2
    assert "unknown id(s) rehabbot/rehab-elbow-v9" in capsys.readouterr().err


def test_step_throughput_makes_the_ids_with_the_robot_asked_for(capsys) -> None:
    assert step_throughput.main(["--steps", "10", "--rounds", "1", "--warmup", "2",
                                 "--ids", "rehab-knee-v1", "--robot", "fr3"]) == 0
    assert "| rehabbot/rehab-knee-v1 (robot=fr3) |" in capsys.readouterr().out


@pytest.mark.slow
def test_bilateral_sync_reads_the_gap_of_symmetric_episodes(capsys) -> None:
    # The expert moves both arms in step: no gap beyond the tolerance, nothing paid.
    expert = bilateral_sync.sync_of("expert", episodes=2, seed=0)
    assert expert["success"] == 1.0 and expert["mean_gap"] == 0.0 and expert["reward_sync"] == 0
    assert bilateral_sync.main(["expert", "--episodes", "1"]) == 0
    assert "| expert | 100 % | 0.000 | 0.000 | 0.00 |" in squeezed(capsys.readouterr().out)


def test_robot_placement_measures_reach_margins_and_the_torque_to_hold_the_limb(capsys):
    rows = robot_placement.measure(["ur5e", "fr3"], [1.75])
    by = {(r["robot"], r["scene"]): r for r in rows}
    for robot in ("ur5e", "fr3"):
        knee = by[(robot, "knee")]
        assert knee["reached"] == knee["poses"] == 25 and knee["margin_rad"] > 0.1
        assert 0.0 < knee["torque_share"] < 1.0 and knee["torque_joint"] == 2
    # The FR3 holds the supine leg at level 4 near its joint-2 limit; the UR5e far from it.
    assert by[("fr3", "hip")]["torque_share"] > by[("ur5e", "hip")]["torque_share"] + 0.2
    assert "| fr3 | knee | 1.75 | 25/25 |" in squeezed(robot_placement.results_markdown(rows))
    assert robot_placement.main(["--robots", "kuka"]) == 2
    assert "unknown robot(s) kuka" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize(("kwargs", "reason"), [
    ({"robot": "fr3", "profile": {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"}},
     "robot joint saturated at rest"),
    ({"profile": {"height_m": 1.75, "mass_kg": 160.0, "sex": "male"}}, "cuff force at rest"),
])
def test_profile_envelope_names_each_refusal_by_its_own_reason(kwargs, reason) -> None:
    # Both messages say "at rest": a torque refusal once counted as a cuff-force one.
    with pytest.raises(ValueError) as refused:
        RehabEnv(limb="hip", **kwargs)
    assert profile_envelope.refusal_reason(str(refused.value)) == reason


def test_expert_agreement_tells_a_trained_agent_from_one_that_pushes_the_wrong_way() -> None:
    # The shipped PPO agent finishes reach-v1 episodes: it moves the way the expert does.
    rows = expert_agreement.agreement("zoo:rehab-reach-v1/ppo", episodes=1, seed=1000,
                                      max_steps=60)
    assert rows[0]["steps"] == 60 and rows[0]["mean_cosine"] > 0.5
    assert rows[0]["opposing_share"] < 0.1
    # The expert against itself: cosine 1, same size.
    expert = expert_agreement.agreement("expert", episodes=1, seed=1000, max_steps=20,
                                        env_id="rehabbot/rehab-reach-v1")
    assert abs(expert[0]["mean_cosine"] - 1.0) < 1e-6
    assert abs(expert[0]["median_norm_ratio"] - 1.0) < 1e-6


@pytest.mark.slow
def test_critic_probe_reads_the_critic_and_scores_its_ranking(tmp_path, monkeypatch) -> None:
    """A trained SBX SAC run (the library's MlpPolicy) is probed end to end (one
    row per target the expert visited, every state counted once); then a critic that prefers
    the expert's direction is ranked right on every state, and its negation on none."""
    pytest.importorskip("sbx")
    import argparse
    import json

    import numpy as np
    import yaml

    from benchmarks.probes import critic_probe
    from rehabbot.cli.train import add_train_parser, cmd_train
    from rehabbot.tasks.observation import THETA, THETA_STAR

    hp = tmp_path / "hp.yml"
    hp.write_text(yaml.safe_dump({
        "policy": "MlpPolicy", "learning_starts": 100, "buffer_size": 2000, "batch_size": 32,
        "train_freq": 4, "gradient_steps": 4, "policy_kwargs": "dict(net_arch=[16, 16])"}))
    parser = argparse.ArgumentParser(prog="rehabbot")
    add_train_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["train", "rehab-reach-v1", "--algo", "sac", "--backend", "sbx",
                              "--hyperparams", str(hp), "--timesteps", "200",
                              "--eval-freq", "0", "--out", str(tmp_path / "runs"),
                              "--env-kwargs", json.dumps({"max_episode_steps": 80}),
                              "--no-progress"])
    assert cmd_train(args) == 0
    model = str(tmp_path / "runs" / "rehab-reach-v1" / "sac" / "seed0" / "model.zip")

    rows = critic_probe.probe(model, episodes=1, seed=1000)
    assert sum(r["states"] for r in rows) == 80  # the expert ran to the 80-step limit
    assert [r["target"] for r in rows] == list(range(len(rows)))
    assert all(np.isfinite(r["mean_gap"]) and 0.0 <= r["ranked_right"] <= 1.0 for r in rows)

    def toward_target(sign: float):
        def factory(_model, _backend):
            def q(obs, act):
                return sign * np.sum(act * (obs[:, THETA_STAR] - obs[:, THETA]), axis=1)
            return q
        return factory

    monkeypatch.setattr(critic_probe, "_critic", toward_target(1.0))
    assert all(r["ranked_right"] == 1.0 and r["mean_gap"] > 0
               for r in critic_probe.probe(model, episodes=1, seed=1000))
    monkeypatch.setattr(critic_probe, "_critic", toward_target(-1.0))
    assert all(r["ranked_right"] == 0.0 for r in critic_probe.probe(model, episodes=1,
                                                                     seed=1000))


def test_stratified_results_cover_every_cell_and_report_per_cell(tmp_path) -> None:
    """Every exercise x weight level x profile gets its episodes (seeds counting up, the same
    for every policy); the table's per-cell counts and IQM come from those episodes."""
    from benchmarks.results import stratified_results

    episodes = stratified_results.evaluate_cells(
        "expert", "rehabbot/rehab-knee-v2", {"max_episode_steps": 3}, 1, 700)
    assert len(episodes) == 2 * 5 * 3
    assert [e["seed"] for e in episodes] == list(range(700, 730))
    assert len({stratified_results.cell_key(e) for e in episodes}) == 30
    assert not any(e["success"] for e in episodes)  # 3 steps: no exercise is done
    fake = [{**e, "success": e["weight_level"] < 4, "safety_violation":
             "cuff_force" if e["weight_level"] == 4 else None} for e in episodes]
    text = squeezed(stratified_results.summarize({
        ("rehabbot/rehab-knee-v2", "sac"): [{"train_seed": 0, "episodes": fake},
                                            {"train_seed": 1, "episodes": fake}],
        ("rehabbot/rehab-knee-v2", "expert"): [{"train_seed": None, "episodes": episodes}]}))
    assert "| rehab-knee-v2 | sac | - | 0, 1 | 80, 80 % | 80 % | 0 % |" in text
    # The validation patients are none of the test patients.
    test_bodies = {json.dumps(p, sort_keys=True) for p in stratified_results.PROFILES.values()}
    assert not test_bodies & {json.dumps(p, sort_keys=True)
                              for p in stratified_results.VALIDATION_PROFILES.values()}
    assert None not in stratified_results.VALIDATION_PROFILES.values()  # not the default body
    assert "| 0 | f160 | 2/2 | 2/2 | 2/2 | 2/2 | 0/2 (2 cuff_force) |" in text


def test_stratified_results_leave_out_the_cells_an_env_refuses() -> None:
    """The FR3 cannot hold the 1.85 m man's leg at weight levels 3 and 4: those cells have no
    episodes (their seeds skipped, so every other cell keeps its seed), are recorded with the
    env's reason and shown as n/a."""
    from benchmarks.results import stratified_results

    refused: list[dict] = []
    kwargs = {"robot": "fr3", "max_episode_steps": 2}
    episodes = stratified_results.evaluate_cells("expert", "rehabbot/rehab-hip-v2", kwargs, 1,
                                                 900, refused)
    assert sorted((c["profile"], c["weight_level"]) for c in refused) == [("m185", 3),
                                                                          ("m185", 4)]
    assert all("fr3_joint" in c["reason"] for c in refused)
    assert len(episodes) == 2 * 5 * 3 - 2 * 2
    kept = {stratified_results.cell_key(e): e["seed"] for e in episodes}
    assert kept[(1, 2, "m185")] == 900 + 2 * 5 * 2 + 5 + 2  # profile, exercise, level order
    assert (0, 3, "m185") not in kept and (1, 4, "m185") not in kept
    text = squeezed(stratified_results.summarize({
        ("rehabbot/rehab-hip-v2 (fr3)", "sac"): [{"train_seed": 0, "episodes": episodes,
                                                  "refused_cells": refused}]}))
    assert "| 0 | m185 | 0/1 | 0/1 | 0/1 | n/a | n/a |" in text
    assert "n/a: the env refuses m185 l3, m185 l4 (no episodes, not counted)" in text
    # Bad arguments are refused at every level: an error, not a table of n/a.
    with pytest.raises(ValueError, match="robot"):
        stratified_results.evaluate_cells("expert", "rehabbot/rehab-hip-v2",
                                          {"robot": "kuka"}, 1, 900)


@pytest.mark.slow
def test_stratified_results_evaluate_a_population_id_on_its_held_out_patients() -> None:
    """A population id's cells are the held-out "test" population's patients, each picked with
    the reset option ``patient`` (its episodes are that patient's: the 1.80 m man's contracture
    changes his targets); a population id is refused with profiles, a one-patient id with
    patients, each naming the profile set to use."""
    from benchmarks.results import stratified_results

    patients = stratified_results.PROFILE_SETS["patients"]
    assert len(patients) == 12 and set(patients) == {
        n for n in patients if n[0] in "fm"}  # named by sex, height and condition
    assert "m180 stiffness_scale=3.0, rom_scale=0.7" in patients
    chosen = {name: patients[name] for name in ("f168 spasticity_mas='3'",
                                                "m180 stiffness_scale=3.0, rom_scale=0.7")}
    episodes = stratified_results.evaluate_cells(
        "expert", "rehabbot/rehab-reach-population-v2", {}, 1, 800, profiles=chosen)
    assert len(episodes) == 2 * 5 * 2
    assert {e["profile"] for e in episodes} == set(chosen)
    assert all(e["patient"] == chosen[e["profile"]]["patient"] for e in episodes)
    # The expert finishes every exercise of both patients, within their own bounds.
    assert all(e["success"] for e in episodes)
    steps = {name: sorted(e["steps"] for e in episodes if e["profile"] == name)
             for name in chosen}
    assert steps["f168 spasticity_mas='3'"] != steps["m180 stiffness_scale=3.0, rom_scale=0.7"]
    with pytest.raises(ValueError, match="--profiles patients"):
        stratified_results.evaluate_cells("expert", "rehabbot/rehab-reach-population-v2", {},
                                          1, 800)
    with pytest.raises(ValueError, match="--profiles test"):
        stratified_results.evaluate_cells("expert", "rehabbot/rehab-reach-v2", {}, 1, 800,
                                          profiles=chosen)


def test_stratified_results_describe_the_populations_they_read(monkeypatch) -> None:
    """The patients page says what the shipped populations hold, read from them: a population
    with another profile and one condition fewer is described so."""
    from benchmarks.results import stratified_results
    from rehabbot.sim.patient import PatientProfile
    from rehabbot.sim.populations import POPULATIONS, PatientPopulation

    def intro() -> str:
        return " ".join(stratified_results.PATIENTS_INTRO.format(
            per_cell=2, seed=50_000, profiles="patients",
            **stratified_results.population_facts()).split())

    shipped = intro()
    assert "(3 profiles x 9 conditions)" in shipped
    assert "2 other profiles, a 1.68 m, 62 kg woman and a 1.80 m, 85 kg man, x 6 other" in shipped
    test = POPULATIONS["test"]
    monkeypatch.setitem(POPULATIONS, "test", PatientPopulation(
        "test", (*test.profiles, PatientProfile(1.90, 100.0, "male")), test.conditions[:-1]))
    changed = intro()
    assert "3 other profiles, a 1.68 m, 62 kg woman and a 1.80 m, 85 kg man and a 1.90 m, " \
           "100 kg man, x 5 other conditions" in changed


def _run_folder(root: Path, seed: int = 0, *, backend: str = "sbx") -> Path:
    """A finished run folder as training leaves it (a manifest and a final model's file)."""
    run_dir = root / "rehab-reach-v2" / "sac" / f"seed{seed}"
    run_dir.mkdir(parents=True)
    (run_dir / "manifest.json").write_text(json.dumps({
        "env_id": "rehabbot/rehab-reach-v2", "algo": "sac", "seed": seed, "backend": backend,
        "timesteps_done": 3000, "hyperparameters": {"policy": "MlpPolicy"}}))
    (run_dir / "model.zip").write_bytes(b"not read here")
    return run_dir


def test_training_curves_read_each_kind_of_run_folder(tmp_path) -> None:
    """A batched run's training log, SB3's evaluations and the monitor files each give the
    success rate against env steps; a folder with none gives no curve; long curves are
    thinned with their ends kept; a broken log is named."""
    import numpy as np

    from benchmarks.results.training_curves import MAX_POINTS, run_curve, thin
    from rehabbot.common.errors import DataError

    batched = _run_folder(tmp_path / "a")
    (batched / "training_log.csv").write_text(
        "iteration,timesteps,success_rate\n1,512,\n2,1024,0.25\n3,1536,0.75\n")
    assert run_curve(batched) == {"source": "training_log.csv", "timesteps": [1024, 1536],
                                  "success_rate": [0.25, 0.75]}
    evaluated = _run_folder(tmp_path / "b")
    (evaluated / "eval").mkdir()
    np.savez(evaluated / "eval" / "evaluations.npz", timesteps=np.array([1000, 2000]),
             results=np.zeros((2, 4)), ep_lengths=np.ones((2, 4)),
             successes=np.array([[0, 0, 1, 0], [1, 1, 1, 0]], dtype=bool))
    assert run_curve(evaluated) == {"source": "eval/evaluations.npz",
                                    "timesteps": [1000, 2000], "success_rate": [0.25, 0.75]}
    monitored = _run_folder(tmp_path / "c")
    (monitored / "monitor").mkdir()
    (monitored / "monitor" / "train_0.monitor.csv").write_text(
        '#{"t_start": 0}\nr,l,t,is_success\n1.0,100,1.0,False\n2.0,100,2.0,True\n')
    assert run_curve(monitored) == {"source": "monitor/*.monitor.csv", "timesteps": [100, 200],
                                    "success_rate": [0.0, 0.5]}
    assert run_curve(_run_folder(tmp_path / "d")) is None
    (batched / "training_log.csv").write_text("iteration,timesteps,success_rate\n1,x,0.5\n")
    with pytest.raises(DataError, match=r"training_log\.csv"):
        run_curve(batched)
    long = thin(np.arange(1000) * 10, np.linspace(0, 1, 1000))
    assert len(long["timesteps"]) == MAX_POINTS
    assert (long["timesteps"][0], long["timesteps"][-1]) == (0, 9990)
    assert long["success_rate"][-1] == 1.0


def test_stratified_results_keep_each_runs_curve_with_its_episodes(tmp_path, monkeypatch):
    """Evaluating a run folder stores its learning curve in the episodes' file, so that the
    page (rendered from that file alone) can draw it."""
    from benchmarks.results import stratified_results

    run_dir = _run_folder(tmp_path / "runs")
    (run_dir / "training_log.csv").write_text("iteration,timesteps,success_rate\n1,512,0.5\n")
    played = []

    def fake_cells(spec, env_id, env_kwargs, per_cell, seed, refused=None,
                   profiles=stratified_results.PROFILES):
        played.append(spec)
        return [{"seed": seed, "profile": "m175", "exercise": 0, "weight_level": 0,
                 "success": True, "safety_violation": None, "steps": 1}]

    monkeypatch.setattr(stratified_results, "evaluate_cells", fake_cells)
    out = tmp_path / "episodes.json"
    assert stratified_results.main([str(tmp_path / "runs"), "--json", str(out)]) == 0
    assert played == [str(run_dir / "model.zip"), "expert"]
    saved = json.loads(out.read_text())
    run = next(e for e in saved["results"] if e["algo"] != "expert")["runs"][0]
    assert run["curve"] == {"source": "training_log.csv", "timesteps": [512],
                            "success_rate": [0.5]}


def test_stratified_results_describe_each_algorithms_training() -> None:
    """n_steps is an off-policy learner's return length but PPO's rollout per env."""
    from benchmarks.results.stratified_results import training_text

    def manifest(algo: str, **kwargs) -> dict:
        return {"algo": algo, "backend": "sbx", "n_envs": 8, "timesteps_done": 1000,
                "hyperparameters": {"policy": "MlpPolicy", "kwargs": kwargs}}

    assert (training_text(manifest("ppo", n_steps=256))
            == "sbx MlpPolicy, 8 envs x 256 steps per update, 1000 steps")
    assert (training_text(manifest("sac", n_steps=10))
            == "sbx MlpPolicy, 10-step returns, 1000 steps")
    assert training_text(manifest("td3")) == "sbx MlpPolicy, 1000 steps"
    # Demonstrations in the buffer and a cloned start are rows of their own.
    from benchmarks.results.stratified_results import row_label

    demos = training_text({**manifest("sac"), "demos": {"episodes": 20}})
    cloned = training_text({**manifest("ppo", n_steps=256), "bc": {"episodes": 20}})
    assert demos.endswith("20 expert episodes in the buffer")
    assert cloned.endswith("actor cloned from 20 expert episodes first")
    assert row_label("sac", {"training": demos}) == "sac + demos"
    assert row_label("ppo", {"training": cloned}) == "ppo + bc"
    assert row_label("ppo + bc", {"training": cloned}) == "ppo + bc"
    assert row_label("ppo", {"training": "sbx MlpPolicy, 1000 steps"}) == "ppo"
    # A batched run says its worlds, and a wall-clock budget that ended it.
    batched = {"backend": "rsl_rl", "n_envs": 4096, "timesteps_done": 98304,
               "hyperparameters": {"actor_hidden_dims": [64, 64], "activation": "tanh",
                                   "num_steps_per_env": 24}}
    assert training_text(batched) == ("rsl_rl PPO on MuJoCo Warp, 64-64 tanh MLPs, 4096 worlds "
                                      "x 24 steps per update, 98304 steps")
    assert training_text({**batched, "time_limit_s": 600.0, "stopped_by": "timesteps"}) == \
        training_text(batched)
    assert training_text({**batched, "time_limit_s": 600.0, "stopped_by": "time_limit"}) == \
        training_text(batched) + " (stopped at its 600 s time limit)"


def test_zoo_select_picks_each_rows_best_seed_on_validation_episodes(tmp_path) -> None:
    """Per env, robot and algorithm the seed with the most successful validation episodes
    (ties: the lower seed); the FR3 runs are a row (and a zoo agent) of their own; test
    episodes are refused."""
    import json

    from benchmarks.results import zoo_select
    from benchmarks.results.stratified_results import env_label

    def run(seed: int, successes: int, robot: str | None = None) -> dict:
        kwargs = {"robot": robot} if robot else {}
        folder = tmp_path / (robot or "ur5e") / f"seed{seed}"
        folder.mkdir(parents=True)
        (folder / "manifest.json").write_text(json.dumps({
            "env_id": "rehabbot/rehab-hip-v2", "algo": "sac", "seed": seed,
            "env_kwargs": kwargs}))
        return {"run_dir": str(folder), "train_seed": seed, "env_kwargs": kwargs,
                "episodes": [{"success": k < successes} for k in range(10)]}

    assert env_label("rehabbot/rehab-hip-v2", {"robot": "fr3"}) == "rehabbot/rehab-hip-v2 (fr3)"
    assert env_label("rehabbot/rehab-hip-v2", {"robot": "ur5e"}) == "rehabbot/rehab-hip-v2"
    validation = {"seed": 40000, "per_cell": 1, "profile_set": "validation",
                  "command": "python ...", "results": [
        {"env_id": "rehabbot/rehab-hip-v2", "algo": "sac + demos",
         "runs": [run(0, 7), run(1, 9), run(2, 9)]},
        {"env_id": "rehabbot/rehab-hip-v2 (fr3)", "algo": "sac + demos",
         "runs": [run(0, 4, "fr3"), run(1, 3, "fr3")]},
        {"env_id": "rehabbot/rehab-hip-v2", "algo": "expert", "runs": [{"episodes": []}]}]}
    picked = zoo_select.choices(validation)
    assert [(c["agent"], c["seed"]) for c in picked] == [("sac", 1), ("sac-fr3", 0)]
    assert picked[0]["success_by_seed"] == {0: 0.7, 1: 0.9, 2: 0.9}
    note = zoo_select.selection_note(picked[0], validation)["selection"]
    assert note["chosen_seed"] == 1 and note["validation_episodes"]["first_seed"] == 40000
    assert note["validation_episodes"]["patients"] == "validation"
    # Choosing on the test episodes or the test patients is refused: a healthy id's episode
    # depends on the patient, not on the seed.
    with pytest.raises(ValueError, match="choose on validation episodes"):
        zoo_select.choices({**validation, "seed": 50000})
    with pytest.raises(ValueError, match="of the test patients"):
        zoo_select.choices({**validation, "profile_set": "test"})


def test_zoo_select_merges_files_and_ships_only_rows_that_learned(tmp_path, capsys) -> None:
    """Several validation files are one record (refused when their episodes differ); a row
    whose best seed finishes fewer than --min-success of its episodes is not shipped."""
    import json

    from benchmarks.results import zoo_select

    def entry(algo: str, successes: int) -> dict:
        folder = tmp_path / algo
        folder.mkdir()
        (folder / "manifest.json").write_text(json.dumps({
            "env_id": "rehabbot/rehab-knee-v2", "algo": algo, "seed": 0, "env_kwargs": {}}))
        return {"env_id": "rehabbot/rehab-knee-v2", "algo": algo, "runs": [
            {"run_dir": str(folder), "train_seed": 0, "env_kwargs": {},
             "episodes": [{"success": k < successes} for k in range(10)]}]}

    files = []
    for name, algo, successes in (("a", "td3", 4), ("b", "ppo", 5)):
        files.append(tmp_path / f"{name}.json")
        files[-1].write_text(json.dumps({"seed": 40000, "per_cell": 1, "command": name,
                                         "profile_set": "validation",
                                         "results": [entry(algo, successes)]}))
    assert zoo_select.main([*map(str, files)]) == 0
    rows = squeezed(capsys.readouterr().out)
    assert "| rehab-knee-v2/td3 | 0 | 0: 40 % |" in rows and "no (below 50 %)" in rows
    assert "| rehab-knee-v2/ppo | 0 | 0: 50 % |" in rows and rows.count("| yes |") == 1
    assert zoo_select.main([*map(str, files), "--min-success", "0.6"]) == 0
    assert squeezed(capsys.readouterr().out).count("| yes |") == 0
    assert zoo_select.main([*map(str, files), "--skip", "rehab-knee-v2/ppo"]) == 0
    assert "no (--skip)" in capsys.readouterr().out
    other = tmp_path / "c.json"
    other.write_text(json.dumps({"seed": 40000, "per_cell": 2, "profile_set": "validation",
                                 "results": []}))
    with pytest.raises(ValueError, match="2 per cell"):
        zoo_select.main([str(files[0]), str(other)])
    with pytest.raises(SystemExit):
        zoo_select.main([str(files[0]), "--min-success", "1.5"])


MUSCLE_JOINT_XML = """
<mujoco>
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="link">
      <joint name="hinge" type="hinge" axis="0 1 0" range="0 2"/>
      <joint name="follower" type="slide" axis="1 0 0" range="-1 1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
    </body>
  </worldbody>
  <equality>
    <joint joint1="follower" joint2="hinge" polycoef="0 0.01 0.002 0 0"/>
  </equality>
  <actuator>
    <muscle name="stretched_by_flexion" joint="hinge" gear="0.05" lengthrange="0 0.1"
            range="0.75 1.05" fpmax="1.3" force="100"/>
  </actuator>
</mujoco>
"""


def test_myo_probe_measures_passive_muscle_torque_and_follows_coupled_joints() -> None:
    """The probe of MyoSuite's models (benchmarks/probes/myo_models.py, which needs myo-sim)
    on a one-muscle joint: a passive muscle that flexion stretches pulls back (negative torque)
    and harder the further it is stretched, with no force while slack; the joint coupled to
    the measured one by a polynomial equality follows it."""
    import mujoco
    import numpy as np

    from benchmarks.probes import myo_models

    model = mujoco.MjModel.from_xml_string(MUSCLE_JOINT_XML)
    hinge = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "hinge")
    coupled = myo_models._coupled_joints(model, hinge)
    assert [joint for joint, _ in coupled] == [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "follower")]
    np.testing.assert_array_equal(coupled[0][1], [0, 0.01, 0.002, 0, 0])
    rows = myo_models.passive_torque_curve(model, "hinge", points=9)
    angles = [row["angle_deg"] for row in rows]
    assert angles[0] == 0.0 and abs(angles[-1] - np.degrees(2.0)) < 1e-9
    torque = np.array([row["total_torque_nm"] for row in rows])
    assert torque[0] == 0.0  # slack at full extension
    assert torque[-1] < 0 and np.all(np.diff(torque) <= 0)  # stretched by flexion: resists
    assert all(row["joint_torque_nm"] == 0.0 for row in rows)  # no joint spring here
    assert model.opt.gravity.tolist() == [0.0, 0.0, 0.0]  # measured without gravity
