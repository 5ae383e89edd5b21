"""The held-out evaluation across the adult envelope (benchmarks/results/heldout_results.py):
its plan of episodes, the expert-relative counting, the cohorts it reads, the page it renders
from its JSON, and the command-line values it refuses."""

from __future__ import annotations

import argparse
import copy
import json
import shutil
from pathlib import Path

import pytest

from benchmarks.common.documents import load_document, render_markdown
from benchmarks.results import heldout_results as heldout
from rehabbot.rl import zoo
from rehabbot.sim.envelope import ENVELOPES, envelope_bodies, envelope_conditions
from rehabbot.sim.patient import PatientProfile

KNEE = heldout.make_target("rehab-knee-v2")
SHORT = heldout.make_target("rehab-knee-v2", {"max_episode_steps": 2})  # 2-step episodes
# The knee's heavy test man resisting at 10 % of his strength pushes harder than the cuff may
# hold: the scene refuses him at every level.
HEAVY = PatientProfile(1.85, 102.0, "male")


def test_the_plan_covers_every_cell_with_seeds_counting_up() -> None:
    """Bodies (8 healthy) then conditions (4 bodies x 6, the tremor 3 episodes per cell), x 2
    exercises x 5 levels; seeds count up from the first; a subset keeps its seeds."""
    patients = heldout.cohort("test", KNEE)
    assert [p.part for p in patients] == ["bodies"] * 8 + ["conditions"] * 24
    plan = heldout.plan_episodes(patients, 2, 60_000, 3)
    assert len(plan) == 8 * 10 + 4 * (5 * 10 + 1 * 10 * 3)
    assert [p.seed for p in plan] == list(range(60_000, 60_000 + len(plan)))
    tremor = [p for p in plan if p.patient.condition.has_tremor]
    assert len(tremor) == 4 * 10 * 3
    assert len({(p.patient, p.exercise, p.weight_level) for p in tremor}) == 4 * 10
    few = heldout.subset(plan, max_bodies=1, exercises=[1], levels=[0, 4])
    assert {p.patient.body for p in few if p.patient.part == "bodies"} == {patients[0].body}
    assert {(p.exercise, p.weight_level) for p in few} == {(1, 0), (1, 4)}
    assert {p.seed: p for p in plan}.items() >= {p.seed: p for p in few}.items()


@pytest.mark.slow
def test_every_controller_plays_the_same_episodes_and_refused_patients_skip_seeds() -> None:
    """The expert and a zoo agent play the same seeds; a patient the scene refuses has no
    episodes, is listed with the scene's reason, and the patient after it keeps the seeds it
    has in the whole plan."""
    patients = [p for p in heldout.cohort("test", SHORT) if p.part == "conditions"
                and p.body in (HEAVY, PatientProfile(1.94, 101.0, "female"))
                and p.condition.effort == "resistive"]
    assert [p.body for p in patients] == [HEAVY, PatientProfile(1.94, 101.0, "female")]
    plan = heldout.subset(heldout.plan_episodes(patients, 2, 500), exercises=[0],
                          levels=[0, 1])
    expert, refused = heldout.evaluate("expert", SHORT, plan)
    agent, _ = heldout.evaluate("zoo:rehab-knee-v2/sac", SHORT, plan)
    assert [e["seed"] for e in expert] == [e["seed"] for e in agent] == [510, 511]
    assert all(e["body"] == "f194 101 kg" and e["steps"] == 2 for e in expert)
    assert [(r["body"], r["weight_level"]) for r in refused] == [("m185 102 kg", 0),
                                                                  ("m185 102 kg", 1)]
    assert all("cuff" in r["reason"] for r in refused)
    data = heldout.target_data(SHORT, plan, [(expert, refused), (agent, [])],
                               [{"kind": "expert", "row": "expert"},
                                {"kind": "zoo", "row": "zoo:rehab-knee-v2/sac"}])
    table = heldout.refused_table(data)
    assert table["rows"] == [["conditions", "m185 102 kg", "resistive 10 %",
                              "0, 1", refused[0]["reason"]]]
    with pytest.raises(ValueError, match="other episodes than the expert"):
        heldout.target_data(SHORT, plan, [(expert, refused), (agent[:1], [])],
                            [{"kind": "expert", "row": "expert"}, {"kind": "zoo", "row": "z"}])


def outcomes(plan, finished) -> list[dict]:
    """Synthetic episodes of ``plan``: finished where ``finished(seed)``, else stopped by the
    cuff-force rule (odd seeds) or the time limit."""
    return [{**p.record(), "success": finished(p.seed), "steps": 10,
             "safety_violation": None if finished(p.seed) or p.seed % 2 == 0 else "cuff_force"}
            for p in plan]


def synthetic_data() -> dict:
    """A test-split document's data without simulation: 10 body episodes (2 bodies x 5
    levels, exercise 0; seeds 60 000-60 004, 60 010-60 014) and 80 condition episodes (2
    bodies x 6 conditions, the tremor's 3 per cell). The expert fails two body episodes and
    two condition ones (one of a tremor's cell), the zoo agent fails exactly those, run seed 0
    also fails 60 000 (a body episode) and run seed 1 60 081 (a condition episode)."""
    plan = heldout.subset(heldout.plan_episodes(heldout.cohort("test", KNEE), 2, 60_000),
                          max_bodies=2, exercises=[0])
    assert len(plan) == 90
    expert_fails = {60_003, 60_013, 60_137, 60_202}
    run = {"kind": "run", "row": "sac + demos", "algo": "sac", "trained_on": "knee-pop",
           "trained_env_id": "rehabbot/rehab-knee-population-v2",
           "env_kwargs": {"patients": "envelope-train"}, "timesteps": 1000,
           "settings": {"backend": "sbx", "demos": 20, "bc": False}}
    controllers = [{"kind": "expert", "row": "expert", "trained_on": "-", "train_seed": None},
                   {"kind": "zoo", "spec": "zoo:rehab-knee-v2/sac", "row": "zoo:rehab-knee-v2/sac",
                    "trained_on": "rehab-knee-v2", "train_seed": 2, "weights_sha256": "ab" * 32},
                   {**run, "train_seed": 0, "run_dir": "r/seed0"},
                   {**run, "train_seed": 1, "run_dir": "r/seed1"}]
    fails = [expert_fails, expert_fails, expert_fails | {60_000}, expert_fails | {60_081}]
    results = [(outcomes(plan, lambda s, f=f: s not in f), []) for f in fails]
    data = {"split": "test", "seed": 60_000, "tremor_episodes": 3, "subset": None,
            "targets": [heldout.target_data(KNEE, plan, results, controllers)]}
    return {**data, "per_controller": heldout.controller_figures(data)}


def test_finished_counts_only_the_episodes_the_expert_finishes() -> None:
    expert = outcomes(heldout.plan_episodes(heldout.cohort("test", KNEE)[:2], 1, 0),
                      lambda s: s % 3 != 0)
    same = [dict(e) for e in expert]
    assert heldout.expert_relative(same, expert) == (6, 6)  # fails only where the expert does
    better = [{**e, "success": True} for e in expert]
    assert heldout.expert_relative(better, expert) == (6, 6)  # its extra wins are not counted
    worse = [{**e, "success": e["success"] and e["seed"] != 1} for e in expert]
    assert heldout.expert_relative(worse, expert) == (5, 6)
    assert heldout.expert_relative(worse, expert, lambda e: e["seed"] < 3) == (1, 2)
    with pytest.raises(ValueError, match="not played"):
        heldout.expert_relative([e for e in worse if e["seed"] != 1], expert)


def test_the_tables_count_from_the_episodes() -> None:
    data = synthetic_data()
    summary = heldout.summary_table(data)
    rows = {row[1]: row for row in summary["rows"]}
    assert set(rows) == {"sac + demos", "zoo:rehab-knee-v2/sac"}
    zoo_row = rows["zoo:rehab-knee-v2/sac"]  # fails only where the expert fails: 100 %
    assert zoo_row[3:8] == ["2", "8/8", "100 %", "78/78", "100 %"]
    runs_row = rows["sac + demos"]  # one more failure each: per seed, and their IQM
    assert runs_row[3:5] == ["0, 1", "7/8, 8/8"] and runs_row[5].startswith("94 [")
    assert runs_row[6] == "78/78, 77/78" and runs_row[7].startswith("99 [")
    assert runs_row[8:] == ["170/180 (94 %)", "86/90 (96 %)"]
    conditions = heldout.breakdown_table(data["targets"][0], "conditions", "condition")
    assert conditions["columns"][1:] == [
        "resistive 10 %", "active 10 %", "active 35 %", "MAS 3", "stiffness x3, ROM x0.7",
        "tremor 6 Hz 1 N·m"]
    assert conditions["rows"][-1][0] == "expert: finished / played"
    assert conditions["rows"][-1][1:] == ["10/10"] * 4 + ["9/10", "29/30"]
    unfinished = heldout.unfinished_table(data["targets"][0])
    assert [(row[0], row[5], row[6]) for row in unfinished["rows"]] == [
        ("bodies", "0/1", "1 cuff_force"), ("bodies", "0/1", "1 cuff_force"),
        ("conditions", "2/3", "1 cuff_force"), ("conditions", "0/1", "1 time limit")]
    assert unfinished["rows"][2][7] == "sac + demos 4/6; zoo:rehab-knee-v2/sac 2/3"
    figures = heldout.zoo_figures(data, "docs/results/x.json")
    assert figures == {"source": "docs/results/x.json", "seed": 60_000, "agents": {
        "rehab-knee-v2/sac": {"bodies": [8, 8], "conditions": [78, 78],
                              "weights_sha256": "ab" * 32}}}
    per_run = {f["run_dir"]: (f["finished"], f["of"]) for f in data["per_controller"]
               if f["kind"] == "run"}
    assert per_run == {"r/seed0": (85, 86), "r/seed1": (85, 86)}


def test_the_cohorts_are_disjoint_and_never_the_training_patient() -> None:
    for limb, robot in ENVELOPES:
        target = heldout.Target(f"rehabbot/rehab-{'reach' if limb == 'arm' else limb}-v2",
                                (("robot", robot),))
        test = {p.body for p in heldout.cohort("test", target)}
        validation = {p.body for p in heldout.cohort("validation", target)}
        train = set(envelope_bodies("train", limb, robot))
        assert test and validation and not (test & validation) and not (test & train)
        assert not validation & train and PatientProfile() not in test | validation
    assert not set(envelope_conditions("validation")) & set(envelope_conditions("test-conditions"))


def test_the_page_renders_from_its_json_and_says_what_held_out_means(tmp_path: Path) -> None:
    data = synthetic_data()
    source = tmp_path / "episodes.json"
    source.write_text(json.dumps({"command": "x", **data}))
    stem = tmp_path / "page"
    assert heldout.main(["--from-json", str(source), "--page", str(stem),
                         "--zoo-figures", str(tmp_path / "zoo.json")]) == 0
    document = load_document(stem.with_suffix(".json"))
    page = stem.with_suffix(".md").read_text()
    assert page == render_markdown(document)
    first = document["intro"].split("\n\n")[0]
    assert first.startswith("**Held out** means")
    for words in ("Latin hypercube", "disjoint from the training and validation bodies",
                  "never the training patient", "distance", "every exercise x weight level",
                  "expert plays the same episodes"):
        assert words in " ".join(first.split())
    assert document["tables"] == heldout.heldout_tables(data)
    assert "| sac + demos " in page and "7/8, 8/8" in page
    assert json.loads((tmp_path / "zoo.json").read_text())["agents"]["rehab-knee-v2/sac"] \
        == {"bodies": [8, 8], "conditions": [78, 78], "weights_sha256": "ab" * 32}
    # Rendering the page's own JSON again gives the same page; one episode changed, another.
    again = tmp_path / "again"
    assert heldout.main(["--from-json", str(stem.with_suffix(".json")), "--page",
                         str(again)]) == 0
    assert load_document(again.with_suffix(".json"))["tables"] == document["tables"]
    changed = copy.deepcopy(data)
    changed["targets"][0]["controllers"][1]["success"][0] = False
    assert heldout.heldout_tables(changed)[0] != document["tables"][0]


def fake_run(folder: Path, model: bool = True) -> Path:
    """A run folder of the knee's population id whose final model is the zoo's knee SAC actor
    (the exported-actor format of a batched run)."""
    folder.mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps({
        "env_id": "rehabbot/rehab-knee-population-v2", "algo": "sac", "seed": 3,
        "backend": "sbx", "env_kwargs": {"patients": "envelope-train"},
        "timesteps_done": 1000, "hyperparameters": {"policy": "MlpPolicy"}}))
    if model:
        shutil.copy(zoo.zoo_path("rehab-knee-v2", "sac"), folder / "policy.npz")
    return folder


@pytest.mark.parametrize(("argv", "named"), [
    (["--env", "rehab-nope-v2"], "rehab-nope-v2"),
    (["--env", "rehab-knee-v2@kuka"], "kuka"),
    (["--env", "rehab-knee-myo-v2"], "rehab-knee-myo-v2"),
    (["--zoo", "rehab-knee-v2/nope"], "rehab-knee-v2/nope"),
    (["--zoo", "rehab-knee-v2/sac", "--exercises", "7"], "--exercises 7"),
    (["--zoo", "rehab-knee-v2/sac", "--workers", "0"], "--workers 0"),
    ([], "nothing to evaluate"),
])
def test_bad_values_are_refused_naming_them(argv, named, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        heldout.main(argv)
    assert exit_info.value.code == 2
    assert named in capsys.readouterr().err


def test_a_run_folder_without_its_final_model_is_refused(tmp_path: Path, capsys) -> None:
    fake_run(tmp_path / "runs" / "seed0")
    unfinished = fake_run(tmp_path / "runs" / "seed1", model=False)
    with pytest.raises(SystemExit) as exit_info:
        heldout.main(["--runs", str(tmp_path / "runs")])
    assert exit_info.value.code == 2 and str(unfinished) in capsys.readouterr().err
    with pytest.raises(SystemExit):
        heldout.main(["--runs", str(tmp_path / "empty")])
    assert str(tmp_path / "empty") in capsys.readouterr().err


@pytest.mark.slow
def test_validation_plays_its_own_cohort_and_gives_each_run_its_figure(tmp_path: Path) -> None:
    """--split validation: the validation bodies x conditions, seeds from 40 000; a run of the
    population id plays in its base id and its finished/of is in the data."""
    target, run = heldout.run_controller(fake_run(tmp_path / "seed3"))
    assert target == heldout.make_target("rehab-knee-v2") and run["row"] == "sac"
    assert run["trained_on"] == "rehab-knee-population-v2 patients=envelope-train"
    short = heldout.Target(target.env_id, (("max_episode_steps", 2),))
    args = argparse.Namespace(split="validation", seed=heldout.SEEDS["validation"],
                              tremor_episodes=3, max_bodies=1, exercises=[0], levels=[2],
                              workers=1)
    expert = {"kind": "expert", "spec": "expert", "row": "expert", "trained_on": "-",
              "train_seed": None}
    data = heldout.evaluate_all({short: [expert, run]}, {short: 2}, args)
    (entry,) = data["targets"]
    assert list(entry["parts"]) == ["validation"]
    assert entry["parts"]["validation"]["conditions"] == [
        c.describe() for c in envelope_conditions("validation")]
    # The 1.89 m, 130 kg man resisting at 8 % pushes harder than the cuff may hold.
    assert [e["seed"] for e in entry["episodes"]] == [40_002, 40_012, 40_022]
    assert [(r["body"], r["condition"], r["weight_level"]) for r in entry["refused"]] == [
        ("m189 130 kg", envelope_conditions("validation")[3].describe(), 2)]
    assert {e["body"] for e in entry["episodes"]} == {
        heldout.body_name(envelope_bodies("validation", "knee")[0])}
    (figure,) = data["per_controller"]
    assert figure["run_dir"] == str(tmp_path / "seed3") and (figure["finished"],
                                                              figure["of"]) == (0, 0)
    assert figure["success"] == [0, 3]  # two steps finish no exercise
    document = heldout.heldout_document(data, "python x.py")
    assert document["tables"][-1]["id"] == "runs"
    assert document["title"].startswith("Validation patients")


@pytest.mark.slow
def test_the_script_runs_end_to_end_on_a_tiny_subset(tmp_path: Path) -> None:
    """The expert and a zoo agent on one body per part, one exercise, one level, in two
    processes: the same episodes as in one, the page and the zoo figures written."""
    args = ["--zoo", "rehab-knee-v2/sac", "--max-bodies", "1", "--exercises", "0",
            "--levels", "3"]
    assert heldout.main([*args, "--json", str(tmp_path / "one.json")]) == 0
    assert heldout.main([*args, "--workers", "2", "--page", str(tmp_path / "page"),
                         "--zoo-figures", str(tmp_path / "zoo.json")]) == 0
    one = json.loads((tmp_path / "one.json").read_text())
    document = load_document(tmp_path / "page.json")
    assert one["targets"] == document["data"]["targets"]
    (target,) = heldout.unpack(one)["targets"]
    assert len(target["episodes"]) == 1 + 5 + 3  # a body; 6 conditions, the tremor's 3
    assert [c["row"] for c in target["controllers"]] == ["expert", "zoo:rehab-knee-v2/sac"]
    figures = json.loads((tmp_path / "zoo.json").read_text())
    assert figures["seed"] == 60_000 and figures["source"] == str(tmp_path / "page.json")
    assert set(figures["agents"]["rehab-knee-v2/sac"]) == {"bodies", "conditions",
                                                           "weights_sha256"}


def test_evaluations_of_the_same_plan_merge_and_others_are_refused():
    data = synthetic_data()
    target = data["targets"][0]
    expert = next(c for c in target["controllers"] if c["kind"] == "expert")
    others = [c for c in target["controllers"] if c["kind"] != "expert"]
    first = {**data, "targets": [{**target, "controllers": [expert, others[0]]}]}
    second = {**data, "targets": [{**target, "controllers": [expert, *others[1:]]}]}
    merged = heldout.merge_data([first, second])
    assert merged["targets"][0]["controllers"] == [expert, *others]
    assert heldout.heldout_tables(merged) == heldout.heldout_tables(data)
    with pytest.raises(ValueError, match="different plans"):
        heldout.merge_data([first, {**second, "seed": 1}])
    shifted = {**target, "episodes": [{**e, "seed": e["seed"] + 1} for e in target["episodes"]]}
    with pytest.raises(ValueError, match="other episodes"):
        heldout.merge_data([first, {**data, "targets": [shifted]}])
    flipped = {**expert, "success": [not expert["success"][0], *expert["success"][1:]]}
    with pytest.raises(ValueError, match="expert played the same episodes differently"):
        heldout.merge_data([first, {**data, "targets": [{**target, "controllers": [
            flipped, *others[1:]]}]}])


def test_stored_data_unpacks_to_the_episodes_and_the_pages_tables_come_from_them():
    data = synthetic_data()
    packed = json.loads(json.dumps(heldout.pack(data)))
    assert isinstance(packed["targets"][0]["episodes"], dict)
    assert heldout.unpack(packed) == data
    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    pages = sorted(results.glob("heldout-*.json"))
    for path in pages:  # every published held-out page: its tables, from its own episodes
        document = json.loads(path.read_text(encoding="utf-8"))
        keys = {sweep: set(heldout.sweep_keys(Path(results.parents[1], sweep)))
                for sweep in document["sweeps"]}
        assert document["tables"] == heldout.heldout_tables(
            heldout.unpack(document["data"]), keys), path.name


def test_the_stops_table_counts_why_expert_finished_episodes_were_not_finished():
    data = synthetic_data()
    target = data["targets"][0]
    table = heldout.stops_table(target)
    expert = heldout.expert_of(target)
    wanted = {e["seed"] for e in expert if e["success"]}
    for _, label, controllers in heldout.rows_of(target):
        for part in target["parts"]:
            row = next(r for r in table["rows"] if r[:2] == [label, part])
            missed = [e for c in controllers for e in heldout.episodes_of(target, c)
                      if e["part"] == part and e["seed"] in wanted and not e["success"]]
            assert row[2] == len(missed) == sum(row[3:])
    flipped = copy.deepcopy(target)
    run = next(c for c in flipped["controllers"] if c["kind"] == "run")
    first = next(i for i, e in enumerate(heldout.episodes_of(flipped, run))
                 if e["seed"] in wanted and e["success"])
    run["success"][first] = False
    assert heldout.stops_table(flipped)["rows"] != table["rows"]
