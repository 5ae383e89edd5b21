"""The clinician's workflow without dead ends: any object with ``predict``
in the evaluator, each episode's patient, the patient-side figures, no overwritten
evaluation, render's progress, extras hints, no third-party warnings, one torch thread."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomllib

import rehabbot  # noqa: F401
from rehabbot.analysis.evaluation import evaluate_policies
from rehabbot.analysis.traces import load_trace
from rehabbot.cli import main
from rehabbot.common.errors import UsageError
from rehabbot.rl.assist_as_needed import AssistAsNeeded

ENV = "rehab-reach-v0"
REPO = Path(__file__).resolve().parent.parent


class Hold:
    """Zero actions: a custom policy with SB3's predict."""

    label = "hold"

    def __init__(self, env) -> None:
        self.shape = env.action_space.shape

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros(self.shape), state


# ------------------------------------------------------------------ 1. any object with predict
def test_evaluator_takes_classes_and_names_together() -> None:
    reports = [r for r, _ in evaluate_policies([Hold, "expert"], ENV, episodes=1)]
    assert [r["policy"]["label"] for r in reports] == ["hold", "expert"]
    assert reports[0]["policy"]["kind"] == "custom"
    assert reports[0]["summary"]["success_rate"] == 0.0  # zero actions reach nothing
    assert reports[1]["summary"]["success_rate"] == 1.0


def test_an_object_bound_to_another_env_is_refused_with_the_remedy() -> None:
    import gymnasium as gym

    env = gym.make(f"rehabbot/{ENV}")
    try:
        with pytest.raises(UsageError) as err:
            evaluate_policies([AssistAsNeeded(env)], ENV, episodes=1)
    finally:
        env.close()
    assert "pass the class (AssistAsNeeded) or a factory" in str(err.value)


def _aan_factory(env):
    policy = AssistAsNeeded(env)
    policy.label = "aan-factory"
    return policy


def test_instance_and_factory_match_the_named_controller() -> None:
    results = evaluate_policies(["aan", AssistAsNeeded, _aan_factory], ENV, episodes=1)
    labels = [r["policy"]["label"] for r, _ in results]
    assert labels == ["aan", "AssistAsNeeded", "aan-factory"]
    returns = [r["per_episode"][0]["return"] for r, _ in results]
    assert returns[0] == returns[1] == returns[2]


@pytest.mark.parametrize(("spec", "needle"), [
    ("no_such_module_xyz:Policy", "no module named 'no_such_module_xyz'"),
    ("json:NoSuchThing", "has no attribute 'NoSuchThing'"),
    ("json:__name__", "has no predict"),
])
def test_bad_module_specs_are_refused_naming_them(spec, needle) -> None:
    with pytest.raises(UsageError) as err:
        evaluate_policies([spec], ENV, episodes=1)
    assert repr(spec) in str(err.value) and needle in str(err.value)


def test_object_without_predict_and_duplicate_labels_are_refused() -> None:
    with pytest.raises(UsageError, match="has no predict"):
        evaluate_policies([object()], ENV, episodes=1)
    with pytest.raises(UsageError, match="two policies are labelled 'hold'"):
        evaluate_policies([Hold, Hold], ENV, episodes=1)


def test_cli_evaluates_a_module_attr_policy(tmp_path, capsys, monkeypatch) -> None:
    (tmp_path / "mypolicies.py").write_text(
        "import numpy as np\n"
        "class Hold:\n"
        "    label = 'hold'\n"
        "    def __init__(self, env):\n"
        "        self.shape = env.action_space.shape\n"
        "    def predict(self, obs, state=None, episode_start=None, deterministic=True):\n"
        "        return np.zeros(self.shape), state\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "mypolicies", raising=False)
    code = main(["evaluate", "mypolicies:Hold", "--env", ENV, "--episodes", "1", "--out",
                 str(tmp_path / "ev")])
    assert code == 0, capsys.readouterr().err
    report = json.loads((tmp_path / "ev" / "hold" / "evaluation.json").read_text())
    assert report["policy"]["kind"] == "custom"
    code = main(["evaluate", "mypolicies:Missing", "--env", ENV, "--episodes", "1", "--out",
                 str(tmp_path / "ev2")])
    assert code == 2
    assert "'mypolicies:Missing'" in capsys.readouterr().err


# ------------------------------------------------------------------ 2. each episode's patient
def test_population_evaluation_records_and_tabulates_each_patient() -> None:
    report, _ = evaluate_policies(["expert"], "rehab-reach-population-v1", episodes=3,
                                  env_kwargs={"patients": "test"})[0]
    from rehabbot.sim.populations import POPULATIONS

    patients = POPULATIONS["test"].patients
    seen = set()
    for episode in report["per_episode"]:
        patient = episode["patient"]
        profile, condition = patients[patient["index"]]
        assert patient["profile"] == {"height_m": profile.height_m, "mass_kg": profile.mass_kg,
                                      "sex": profile.sex}
        assert patient["condition"] == (None if condition.is_healthy else condition.to_dict())
        seen.add(patient["index"])
    assert len(report["per_patient"]) == len(seen) >= 2
    assert sum(entry["episodes"] for entry in report["per_patient"]) == 3
    from rehabbot.analysis.evaluation import format_patient_tables

    table = format_patient_tables([report])
    for entry in report["per_patient"]:
        assert entry["patient"]["description"] in table


def test_single_patient_evaluation_names_its_patient() -> None:
    report, _ = evaluate_policies(["expert"], "rehab-reach-v2", episodes=1,
                                  env_kwargs={"condition": {"spasticity_mas": "2"}})[0]
    patient = report["per_episode"][0]["patient"]
    assert patient["index"] is None and patient["condition"]["spasticity_mas"] == "2"
    assert patient["profile"] == {"height_m": 1.75, "mass_kg": 75.0, "sex": "male"}


# ------------------------------------------------------------------ 3. patient-side figures
@pytest.fixture(scope="module")
def expert_trace(tmp_path_factory):
    from rehabbot.analysis.evaluation import save_report

    report, trace = evaluate_policies(["expert"], ENV, episodes=1)[0]
    folder = tmp_path_factory.mktemp("ev") / "expert"
    save_report(report, trace, folder)
    return load_trace(folder / "trace.npz"), trace


def _lines(ax) -> dict[str, object]:
    """The axes' lines by their gid (what each one is)."""
    return {line.get_gid(): line for line in ax.get_lines()}


def test_patient_joint_figure_draws_angles_path_and_bounds(expert_trace) -> None:
    pytest.importorskip("matplotlib")
    from rehabbot.analysis.patient_figures import build_patient_joints

    trace, raw = expert_trace
    figure = build_patient_joints(trace)
    axes = [ax for ax in figure.axes if ax.get_visible()]
    assert len(axes) == 3
    for j, ax in enumerate(axes):
        lines = _lines(ax)
        np.testing.assert_array_equal(lines["measured"].get_ydata(),
                                      np.degrees(raw["patient_qpos_rad"][:, j]))
        prescribed = raw["target_patient_deg"][raw["target_index"], j]
        np.testing.assert_array_equal(lines["prescribed"].get_ydata(), prescribed)
        low, high = trace.patient_range_deg[j]
        bounds = sorted(line.get_ydata()[0] for line in ax.get_lines()
                        if line.get_linestyle() == ":")
        assert bounds == [low, high] and low < high
        assert lines["rom-low"].get_label() == (f"range of motion {low:g}° to {high:g}°\n"
                                                "(AAOS normal range; stop 2° beyond)")


def test_cuff_force_and_work_figures(expert_trace) -> None:
    pytest.importorskip("matplotlib")
    from rehabbot.analysis.patient_figures import build_cuff_force, build_work

    trace, raw = expert_trace
    ax = build_cuff_force(trace).axes[0]
    lines = _lines(ax)
    np.testing.assert_array_equal(lines["cuff-force"].get_ydata(), raw["interaction_force_n"])
    assert lines["force-limit"].get_ydata()[0] == float(trace.cuff_force_limit_n) == 140.0
    assert lines["force-limit"].get_label() == ("limit 140 N\n(ISO/TS 15066 quasi-static, "
                                                "hands and fingers)")
    ax = build_work(trace).axes[0]
    lines = _lines(ax)
    robot = lines["robot-work"].get_ydata()
    assert robot[0] == 0.0 and robot[-1] > 0.0  # the robot does the work of a passive limb
    np.testing.assert_array_equal(lines["patient-work"].get_ydata(), raw["patient_work_j"])


@pytest.mark.slow
def test_plot_cli_writes_the_patient_figures(expert_trace, tmp_path, capsys) -> None:
    pytest.importorskip("matplotlib")
    trace, _ = expert_trace
    assert main(["plot", str(trace.path.parent), "--out", str(tmp_path), "--formats",
                 "png"]) == 0
    names = {Path(line).name for line in capsys.readouterr().out.split()}
    for prefix in ("fig7_patient_joints", "fig8_cuff_force", "fig9_work"):
        assert f"{prefix}_expert_rehab-reach-v0.png" in names
    assert main(["plot", str(trace.path.parent), "--out", str(tmp_path / "b"), "--formats",
                 "png", "--no-patient-figures"]) == 0
    assert "fig7" not in capsys.readouterr().out


# ------------------------------------------------------------------ 5. no overwritten evaluation
def test_evaluate_refuses_an_earlier_evaluation_without_overwrite(tmp_path, capsys,
                                                                  monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", "expert", "--env", ENV, "--episodes", "1"]
    assert main(args) == 0  # its default folder, runs/evaluation/rehab-reach-v0/expert
    default = tmp_path / "runs" / "evaluation" / ENV / "expert"
    first = (default / "expert" / "evaluation.json").read_text()
    capsys.readouterr()
    assert main([*args, "--seed", "3"]) == 2  # the same comparison again: would mix
    err = capsys.readouterr().err
    assert "already holds an evaluation" in err and "--overwrite" in err
    assert (default / "expert" / "evaluation.json").read_text() == first
    assert main([*args, "--seed", "3", "--overwrite"]) == 0
    report = json.loads((default / "expert" / "evaluation.json").read_text())
    assert report["episode_seeds"] == [3]


# ------------------------------------------------------------------ 6. render's progress, help
@pytest.mark.slow
def test_render_prints_progress_to_stderr(tmp_path, capsys) -> None:
    pytest.importorskip("imageio")
    code = main(["render", "expert", "--env", ENV, "--out", str(tmp_path / "a.gif"),
                 "--width", "64", "--height", "48", "--frame-every", "25",
                 "--env-kwargs", '{"max_episode_steps": 100}'])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    lines = [line for line in captured.err.splitlines() if line.startswith("rehabbot render:")]
    assert re.fullmatch(r"rehabbot render: frame 1/5 \(20 %\), 0:\d\d elapsed, ~\d+:\d\d left",
                        lines[0])
    assert re.fullmatch(r"rehabbot render: frame (\d+)/\1 \(100 %\), \d+:\d\d elapsed, done",
                        lines[-1])


def test_progress_line_is_throttled_and_estimates_time_left() -> None:
    import io

    from rehabbot.cli.progress import ProgressLine

    now = [0.0]
    stream = io.StringIO()
    progress = ProgressLine("x", stream=stream, interval_s=2.0, clock=lambda: now[0])
    for done in range(1, 11):
        now[0] = float(done)  # one second per frame
        progress(done, 10)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "x: frame 1/10 (10 %), 0:01 elapsed, ~0:09 left"
    assert lines[-1] == "x: frame 10/10 (100 %), 0:10 elapsed, done"
    assert len(lines) == 6  # frames 1, 3, 5, 7, 9 and the last


@pytest.mark.parametrize("command", ["render", "evaluate"])
def test_help_names_aan(command, capsys) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "'aan'" in capsys.readouterr().out


# ------------------------------------------------------------------ 7. extras hints
def _pyproject_extras() -> dict[str, set[str]]:
    data = tomllib.loads((REPO / "pyproject.toml").read_text())
    extras = {}
    for extra, requirements in data["project"]["optional-dependencies"].items():
        extras[extra] = {re.split(r"[\[<>=!~ ;]", r, maxsplit=1)[0].lower() for r in requirements}
    return extras


def test_every_optional_module_maps_to_the_extra_that_installs_it() -> None:
    from rehabbot.common.extras import OPTIONAL_MODULES, install_hint

    extras = _pyproject_extras()
    for module, (distribution, extra) in OPTIONAL_MODULES.items():
        assert distribution in extras[extra], (module, distribution, extra)
        assert install_hint(module) == f'pip install "rehabbot[{extra}]"'
    assert install_hint("yaml") == 'pip install "rehabbot[train]"'
    assert install_hint("ray.tune") == 'pip install "rehabbot[sweep]"'
    with pytest.raises(ValueError, match="'numpy' is not an optional dependency"):
        install_hint("numpy")


def test_a_missing_optional_module_is_reported_with_its_extra() -> None:
    from rehabbot.cli.errors import as_cli_error

    err = ModuleNotFoundError("No module named 'yaml'", name="yaml")
    assert str(as_cli_error(err)).endswith('pip install "rehabbot[train]"')


# ------------------------------------------------------------------ 8. no third-party warnings
def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONWARNINGS": "default", "PYTHONPATH": str(REPO),
           "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-W", "default", "-m", "rehabbot", *args], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=300, check=False)


@pytest.mark.slow
def test_evaluate_and_plot_write_no_warning_to_stderr(tmp_path) -> None:
    pytest.importorskip("matplotlib")
    done = _cli(["evaluate", "expert", "--env", "rehab-reach-v1", "--episodes", "1", "--out",
                 "ev"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Warning" not in done.stderr and "WARN" not in done.stderr, done.stderr
    done = _cli(["plot", "ev", "--out", "figs", "--formats", "png"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Warning" not in done.stderr and "WARN" not in done.stderr, done.stderr


def test_the_evaluator_does_not_pass_on_gymnasiums_out_of_date_warning(recwarn) -> None:
    evaluate_policies(["expert"], "rehab-reach-v1", episodes=1)
    assert not [w for w in recwarn if "out of date" in str(w.message)]


# ------------------------------------------------------------------ 9. one torch thread
def test_one_torch_thread_unless_the_user_chose(monkeypatch) -> None:
    torch = pytest.importorskip("torch")
    from rehabbot.cli.threads import one_torch_thread

    before = torch.get_num_threads()
    try:
        monkeypatch.setenv("OMP_NUM_THREADS", "3")
        assert not one_torch_thread(["model.zip"])
        monkeypatch.delenv("OMP_NUM_THREADS")
        assert not one_torch_thread(["expert", "zoo:rehab-reach-v1/ppo"])  # no torch needed
        torch.set_num_threads(2)
        assert one_torch_thread(["model.zip"]) and torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
