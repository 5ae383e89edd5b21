"""``make demo`` (``rehabbot demo``): train, evaluate, plot, summarise; resumable."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rehabbot.cli import demo, main

pytestmark = pytest.mark.slow  # trains SAC, evaluates, plots: about 60 s


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory) -> tuple[Path, int, str]:
    out = tmp_path_factory.mktemp("demo")
    code = main(["demo", "--out", str(out), "--timesteps", "2100", "--demos", "1",
                 "--episodes", "2", "--no-video", "--no-progress"])
    return out, code, (out / "summary.md").read_text() if (out / "summary.md").exists() else ""


def test_demo_trains_evaluates_plots_and_summarises(demo_out, capsys) -> None:
    out, code, summary_md = demo_out
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["train_timesteps"] == 2100  # > 2 episodes: Fig. 4 has data
    assert summary["expert_episodes_in_buffer"] == 1
    assert set(summary["results"]) == {"sac-seed0", "expert", "random"}
    # The scripted expert finishes every episode; random actions never do.
    assert summary["results"]["expert"]["success_rate"] == 1.0
    assert summary["results"]["random"]["success_rate"] == 0.0
    assert summary["eval_seeds"] == [demo.EVAL_SEED, demo.EVAL_SEED + 1]
    for label in summary["results"]:
        assert (out / "evaluation" / label / "evaluation.json").is_file()
        assert (out / "evaluation" / label / "trace.npz").is_file()
    names = {Path(p).name for p in summary["figures"]}
    assert "fig4_learning_curves.png" in names and "fig4_learning_curves.pdf" in names
    for fig in ("fig3_tool_path", "fig5_kinematics", "fig6_torques"):
        # One figure per evaluated policy.
        assert sum(name.startswith(fig) and name.endswith(".png") for name in names) == 3
    assert all(Path(p).stat().st_size > 1000 for p in summary["figures"])
    assert "| success rate" in summary_md
    assert "rehabbot train rehab-knee-v2 --algo sac" in summary_md
    assert "--hyperparams sac" in summary_md and "--demos 1" in summary_md
    assert set(summary["stage_wall_clock_s"]) == {"train", "evaluate", "plot"}


def test_demo_run_again_resumes_instead_of_retraining(demo_out) -> None:
    out, _code, _md = demo_out
    manifest_path = out / "runs" / "rehab-knee-v2" / "sac" / "seed0" / "manifest.json"
    before = json.loads(manifest_path.read_text())
    code = main(["demo", "--out", str(out), "--timesteps", "2500", "--demos", "1",
                 "--episodes", "1", "--no-video", "--no-progress"])
    after = json.loads(manifest_path.read_text())
    assert code == 0
    assert before["timesteps_done"] == 2100 and after["timesteps_done"] == 2500
    assert after["started_at"] == before["started_at"]  # the same run, extended


def test_demo_reports_an_unwritable_output_folder(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["demo", "--out", str(blocker / "demo"), "--timesteps", "300"]) == 2
    err = capsys.readouterr().err
    assert "rehabbot: error: --out" in err and f"{str(blocker)!r} is not a folder" in err
