"""Tests of the figures (:mod:`rehabbot.analysis`) and ``rehabbot plot`` on synthetic run
directories and traces."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import types
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.collections import PolyCollection
from mpl_toolkits.mplot3d import proj3d

from rehabbot.analysis import figures, learning_curves, plotting, traces
from rehabbot.cli import EXIT_FAILURE, EXIT_USAGE, CliError
from rehabbot.cli import plot as plot_cli

ENV_ID = "rehabbot/rehab-reach-v0"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")


# --------------------------------------------------------------------------- builders


def write_monitor(path: Path, rows: Sequence[tuple[float, int, float, bool, str]]) -> None:
    """An SB3 Monitor file: JSON comment, header, one row per episode (r, l, t, succ, rule)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ['#{"t_start": 1700000000.0, "env_id": "rehabbot/rehab-reach-v0"}',
             "r,l,t,is_success,safety_violation"]
    lines += [f"{r},{ln},{t},{succ},{rule}" for r, ln, t, succ, rule in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def make_run(root: Path, algo: str, seed: int, returns: Sequence[float],
             length: int = 100, successes: Sequence[bool] | None = None,
             env_id: str = ENV_ID, model: bool = False) -> Path:
    """A run directory with a manifest and one monitor file of fixed-length episodes."""
    run_dir = root / env_id.split("/")[-1] / algo / f"seed{seed}"
    run_dir.mkdir(parents=True)
    n = len(returns)
    manifest = {"env_id": env_id, "algo": algo, "seed": seed, "total_timesteps": n * length,
                "timesteps_done": n * length, "status": "done", "n_envs": 1}
    (run_dir / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    succ = successes if successes is not None else [False] * n
    rows = [(float(r), length, 0.5 * (i + 1), bool(s), "")
            for i, (r, s) in enumerate(zip(returns, succ, strict=True))]
    write_monitor(run_dir / "monitor" / "train_0.monitor.csv", rows)
    if model:
        (run_dir / "model.zip").write_bytes(b"PK\x05\x06" + b"\x00" * 18)
    return run_dir


def make_trace(path: Path, policy: str = "sac-seed0", env_id: str = ENV_ID,
               dt_s: float = 0.01, duration_s: float = 4.0) -> dict[str, np.ndarray]:
    """A trace whose joint j follows A_j sin(ω t); torque j peaks at 10 (j + 1) N·m."""
    t = np.arange(0.0, duration_s, dt_s)
    omega = 2 * np.pi * 0.5
    amplitudes = np.array([0.2, 0.4, 0.6, 0.8, 1.0, 1.2])
    qpos = amplitudes * np.sin(omega * t)[:, None]
    torque = (10.0 * np.arange(1, 7)) * np.cos(omega * t)[:, None]
    tool = np.stack([0.4 + 0.1 * np.cos(omega * t), 0.1 * np.sin(omega * t), 0.3 + 0.05 * t],
                    axis=1)
    targets = np.array([[0.5, 0.0, 0.3], [0.4, 0.1, 0.4], [0.3, 0.0, 0.5]])
    data = {
        "env_id": np.array(env_id), "policy": np.array(policy), "seed": np.array(0),
        "dt_s": np.array(dt_s), "time_s": t, "robot_qpos_rad": qpos,
        "robot_torque_nm": torque, "torque_limit_nm": np.array([150, 150, 150, 28, 28, 28.0]),
        "joint_names": np.array(JOINTS), "tool_pos_m": tool, "target_tool_pos_m": targets,
        "target_robot_rad": np.zeros((3, 6)), "target_index": np.minimum(t // 1.5, 2).astype(int),
        "patient_qpos_rad": np.zeros((len(t), 3)), "interaction_force_n": np.zeros(len(t)),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **data)
    return data


def linear_returns(offset: float, n: int, length: int = 100) -> np.ndarray:
    """Return of episode i = offset + 0.01 × (steps when it finished)."""
    return offset + 0.01 * length * np.arange(1, n + 1)


@pytest.fixture
def experiment(tmp_path: Path) -> Path:
    """PPO × 2 seeds and SAC × 3 seeds with linear returns; SAC seed 2 stops earliest."""
    root = tmp_path / "runs"
    make_run(root, "ppo", 0, linear_returns(0.0, 60), successes=[False] * 60)
    make_run(root, "ppo", 1, linear_returns(10.0, 50), successes=[True] * 50)
    make_run(root, "sac", 0, linear_returns(100.0, 60), successes=[True] * 60)
    make_run(root, "sac", 1, linear_returns(110.0, 60), successes=[True, False] * 30)
    make_run(root, "sac", 2, linear_returns(120.0, 40), successes=[True] * 40)
    return root


def assert_png(path: Path) -> None:
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_MAGIC


def assert_pdf(path: Path) -> None:
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:4] == b"%PDF"


def plot_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rehabbot")
    commands = parser.add_subparsers(dest="command", required=True)
    plot_cli.add_plot_parser(commands)
    return parser


# --------------------------------------------------------------------------- loading


def test_import_does_not_load_matplotlib() -> None:
    code = ("import sys, rehabbot.analysis.plotting, rehabbot.cli.plot; "
            "sys.exit('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_load_runs_reads_manifests_and_episodes(experiment: Path) -> None:
    runs = learning_curves.load_runs([experiment])
    assert sorted((run.algo, run.seed) for run in runs) == [
        ("ppo", 0), ("ppo", 1), ("sac", 0), ("sac", 1), ("sac", 2)]
    sac1 = next(run for run in runs if (run.algo, run.seed) == ("sac", 1))
    assert sac1.env_id == ENV_ID and sac1.manifest["n_envs"] == 1
    np.testing.assert_allclose(sac1.steps, 100.0 * np.arange(1, 61))
    np.testing.assert_allclose(sac1.returns, linear_returns(110.0, 60))
    np.testing.assert_allclose(sac1.lengths, 100.0)
    np.testing.assert_allclose(sac1.successes[:4], [1, 0, 1, 0])
    # the same run given twice (root and run dir) is loaded once
    assert len(learning_curves.load_runs([experiment, sac1.path])) == 5


def test_sub_env_monitors_are_merged_by_time(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path, "td3", 0, [1.0])
    write_monitor(run_dir / "monitor" / "train_0.monitor.csv",
                  [(1.0, 10, 1.0, True, ""), (3.0, 10, 3.0, False, "")])
    write_monitor(run_dir / "monitor" / "train_1.monitor.csv",
                  [(2.0, 20, 2.0, False, "force"), (4.0, 20, 4.0, True, "")])
    run = learning_curves.load_runs([run_dir])[0]
    np.testing.assert_allclose(run.returns, [1, 2, 3, 4])
    np.testing.assert_allclose(run.steps, [10, 30, 40, 60])
    np.testing.assert_allclose(run.successes, [1, 0, 0, 1])


def test_rolling_mean_is_trailing_and_ignores_nan() -> None:
    values = np.array([1.0, 2.0, np.nan, 4.0, 5.0])
    np.testing.assert_allclose(learning_curves.rolling_mean(values, 2), [1.0, 1.5, 2.0, 4.0, 4.5])
    np.testing.assert_allclose(learning_curves.rolling_mean(values, 1)[[0, 1, 3]], [1, 2, 4])


# --------------------------------------------------------------------------- Fig. 4


def _lines(ax) -> list:
    return [line for line in ax.get_lines() if not line.get_label().startswith("_")]


def test_fig4_one_line_per_algorithm_with_band(experiment: Path) -> None:
    runs = learning_curves.load_runs([experiment])
    figures = learning_curves.build_learning_curves(runs, smooth=20)
    assert list(figures) == [ENV_ID]
    axes = figures[ENV_ID].axes
    assert len(axes) == 3
    for ax in axes:
        assert [line.get_label() for line in _lines(ax)] == ["PPO (2 seeds)", "SAC (3 seeds)"]
        bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert len(bands) == 2
    assert "return" in axes[0].get_ylabel() and "length" in axes[1].get_ylabel()
    assert "success" in axes[2].get_ylabel()
    assert all(ax.get_xlabel() == "environment steps" for ax in axes)


def test_fig4_mean_over_seeds_and_common_step_range(experiment: Path) -> None:
    runs = learning_curves.load_runs([experiment])
    axes = learning_curves.build_learning_curves(runs, smooth=1)[ENV_ID].axes
    ppo, sac = _lines(axes[0])
    # only up to the steps all seeds reached: PPO seed 1 has 50 episodes, SAC seed 2 has 40
    assert sac.get_xdata()[-1] == pytest.approx(4000.0)
    assert ppo.get_xdata()[-1] == pytest.approx(5000.0)
    assert sac.get_xdata()[0] == pytest.approx(100.0)
    for step in (100.0, 1234.0, 3999.0):
        expected = np.mean([100.0, 110.0, 120.0]) + 0.01 * step
        assert np.interp(step, sac.get_xdata(), sac.get_ydata()) == pytest.approx(expected)
    assert np.interp(2500.0, ppo.get_xdata(), ppo.get_ydata()) == pytest.approx(5.0 + 25.0)
    # success panel: PPO seeds always fail / always succeed -> mean 0.5, std 0.5
    ppo_success = _lines(axes[2])[0]
    np.testing.assert_allclose(ppo_success.get_ydata(), 0.5)
    band = next(c for c in axes[2].collections if isinstance(c, PolyCollection))
    vertices = band.get_paths()[0].vertices
    assert vertices[:, 1].min() == pytest.approx(0.0) and vertices[:, 1].max() == pytest.approx(1)
    np.testing.assert_allclose(_lines(axes[1])[0].get_ydata(), 100.0)


def test_fig4_default_smoothing_of_constant_returns(tmp_path: Path) -> None:
    for seed, value in enumerate((3.0, 5.0, 10.0)):
        make_run(tmp_path, "sac", seed, [value] * 30)
    runs = learning_curves.load_runs([tmp_path])
    line = _lines(learning_curves.build_learning_curves(runs)[ENV_ID].axes[0])[0]
    np.testing.assert_allclose(line.get_ydata(), 6.0)


def test_fig4_smoothing_is_a_rolling_mean(tmp_path: Path) -> None:
    make_run(tmp_path, "ppo", 0, [0.0, 10.0] * 20)  # alternates, window 2 -> constant 5
    runs = learning_curves.load_runs([tmp_path])
    line = _lines(learning_curves.build_learning_curves(runs, smooth=2)[ENV_ID].axes[0])[0]
    assert line.get_label() == "PPO (1 seed)"
    steps = line.get_xdata()
    values = line.get_ydata()
    np.testing.assert_allclose(values[steps >= 200], 5.0)


def test_plot_learning_curves_writes_png_and_pdf(experiment: Path, tmp_path: Path) -> None:
    out = tmp_path / "figs"
    written = learning_curves.plot_learning_curves(learning_curves.load_runs([experiment]), out)
    assert written == [out / "fig4_learning_curves.png", out / "fig4_learning_curves.pdf"]
    assert_png(written[0])
    assert_pdf(written[1])


def test_fig4_one_figure_per_env_id(experiment: Path, tmp_path: Path) -> None:
    make_run(experiment, "sac", 0, [1.0] * 10, env_id="rehabbot/rehab-knee-v0")
    out = tmp_path / "figs"
    written = learning_curves.plot_learning_curves(learning_curves.load_runs([experiment]), out,
                                            formats=("png",))
    assert sorted(path.name for path in written) == [
        "fig4_learning_curves_rehab-knee-v0.png", "fig4_learning_curves_rehab-reach-v0.png"]


def test_fig4_from_evaluations(tmp_path: Path) -> None:
    for seed, offset in enumerate((0.0, 2.0)):
        run_dir = make_run(tmp_path, "td3", seed, [0.0] * 5)
        (run_dir / "eval").mkdir()
        steps = np.array([1000, 2000, 3000])
        results = offset + np.array([[1.0, 3.0], [5.0, 7.0], [9.0, 11.0]])
        np.savez(run_dir / "eval" / "evaluations.npz", timesteps=steps, results=results,
                 ep_lengths=np.full((3, 2), 50), successes=np.array([[0, 0], [0, 1], [1, 1]]))
    runs = learning_curves.load_runs([tmp_path])
    axes = learning_curves.build_learning_curves(runs, source="eval")[ENV_ID].axes
    ret, length, success = (_lines(ax)[0] for ax in axes)
    assert ret.get_label() == "TD3 (2 seeds)"
    assert np.interp(2000, ret.get_xdata(), ret.get_ydata()) == pytest.approx(7.0)
    np.testing.assert_allclose(length.get_ydata(), 50.0)
    assert np.interp(3000, success.get_xdata(), success.get_ydata()) == pytest.approx(1.0)
    assert np.interp(2000, success.get_xdata(), success.get_ydata()) == pytest.approx(0.5)
    without_eval = make_run(tmp_path / "other", "td3", 0, [0.0] * 5)
    with pytest.raises(ValueError, match=r"no run has evaluations"):
        learning_curves.build_learning_curves(learning_curves.load_runs([without_eval]),
                                              source="eval")


# --------------------------------------------------------------------------- Figs. 5, 6, 3


@pytest.fixture
def trace_file(tmp_path: Path) -> Path:
    path = tmp_path / "runs" / "rehab-reach-v0" / "sac" / "seed0" / "evaluation" / "trace.npz"
    make_trace(path)
    return path


def test_fig5_velocity_peak_of_sine_joints(trace_file: Path) -> None:
    figure = figures.build_kinematics(trace_file)
    velocity_ax, acceleration_ax, jerk_ax = figure.axes[:3]
    omega = 2 * np.pi * 0.5
    amplitudes = [0.2, 0.4, 0.6, 0.8, 1.0, 1.2]
    for ax in (velocity_ax, acceleration_ax, jerk_ax):
        assert [line.get_label() for line in _lines(ax)] == list(JOINTS)
    assert [t.get_text() for t in velocity_ax.get_legend().get_texts()] == list(JOINTS)
    for line, amplitude in zip(_lines(velocity_ax), amplitudes, strict=True):
        assert np.max(np.abs(line.get_ydata())) == pytest.approx(amplitude * omega, rel=0.01)
    # acceleration and jerk away from the one-sided edges
    interior = slice(10, -10)
    accel = _lines(acceleration_ax)[5].get_ydata()[interior]
    jerk = _lines(jerk_ax)[5].get_ydata()[interior]
    assert np.max(np.abs(accel)) == pytest.approx(1.2 * omega**2, rel=0.01)
    assert np.max(np.abs(jerk)) == pytest.approx(1.2 * omega**3, rel=0.01)
    assert "velocity" in velocity_ax.get_ylabel() and jerk_ax.get_xlabel() == "time [s]"


def test_fig5_uses_metrics_finite_differences(trace_file: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def fake(position: np.ndarray, dt_s: float) -> tuple[np.ndarray, ...]:
        calls.append(dt_s)
        return np.ones_like(position), 2 * np.ones_like(position), 3 * np.ones_like(position)

    fake_metrics = types.ModuleType("rehabbot.analysis.metrics")
    fake_metrics.finite_differences = fake  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "rehabbot.analysis.metrics", fake_metrics)
    figure = figures.build_kinematics(trace_file)
    assert calls == [pytest.approx(0.01)]
    np.testing.assert_allclose(_lines(figure.axes[2])[0].get_ydata(), 3.0)


def test_fig6_torques_with_limits(trace_file: Path) -> None:
    figure = figures.build_torques(trace_file)
    axes = [ax for ax in figure.axes if ax.get_visible()]
    assert len(axes) == 6
    limits = [150, 150, 150, 28, 28, 28]
    for j, ax in enumerate(axes):
        assert ax.get_title() == f"{JOINTS[j]} (limit ±{limits[j]} N·m)"
        lines = ax.get_lines()
        torque = next(line for line in lines if line.get_linestyle() == "-")
        assert np.max(torque.get_ydata()) == pytest.approx(10.0 * (j + 1))
        dashed = sorted(float(line.get_ydata()[0]) for line in lines
                        if line.get_linestyle() == "--")
        assert dashed == [-limits[j], limits[j]]
        labelled = [line.get_label() for line in lines if line.get_gid() == "torque-limit"
                    and not line.get_label().startswith("_")]
        assert labelled == [f"limit ±{limits[j]} N·m\n(source not recorded)"]
        low, high = ax.get_ylim()  # limits and the whole torque curve (wrists exceed) visible
        assert low < -limits[j] and high > limits[j]
        assert low <= -10.0 * (j + 1) and high >= 10.0 * (j + 1)


def test_fig3_tool_path(trace_file: Path) -> None:
    from matplotlib.colors import to_hex

    data = np.load(trace_file)
    figure = figures.build_tool_path(trace_file)
    ax = figure.axes[0]
    assert ax.name == "3d"
    purple = [line for line in ax.get_lines() if to_hex(line.get_color()) == "#8000c0"]
    assert len(purple) == 1
    xs, ys, zs = purple[0].get_data_3d()
    np.testing.assert_allclose(np.stack([xs, ys, zs], axis=1), data["tool_pos_m"])
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 1
    np.testing.assert_allclose(np.stack(dashed[0].get_data_3d(), axis=1),
                               data["target_tool_pos_m"])
    assert [text.get_text().strip() for text in ax.texts] == ["1", "2", "3"]
    spans = [np.diff(lim)[0] for lim in (ax.get_xlim(), ax.get_ylim(), ax.get_zlim())]
    np.testing.assert_allclose(spans, spans[0])
    assert ax.get_xlabel() == "x [m]" and ax.get_zlabel() == "z [m]"


def make_target_trace(path: Path, targets_m: np.ndarray) -> Path:
    """:func:`make_trace` with the given targets (N, 3)."""
    data = make_trace(path)
    data["target_tool_pos_m"] = np.asarray(targets_m, dtype=float)
    data["target_robot_rad"] = np.zeros((len(targets_m), 6))
    np.savez(path, **data)
    return path


def drawn_labels(figure) -> tuple[list[str], np.ndarray]:
    """Fig. 3's label texts and where they land on the page [pt] once drawn."""
    figure.canvas.draw()
    ax = figure.axes[0]
    xyz = np.array([text.get_position_3d() for text in ax.texts]).reshape(-1, 3)
    return [text.get_text().strip() for text in ax.texts], figures._page_points_pt(ax, xyz)


def target_markers(ax):
    return next(c for c in ax.collections if c.get_label().startswith("targets"))


def test_fig3_coinciding_targets_share_one_label(tmp_path: Path) -> None:
    # out 1..5, then back to (1 mm from) target 2, as a reaching exercise revisits a pose
    targets = np.array([[0.5, 0.0, 0.3], [0.45, 0.05, 0.35], [0.4, 0.1, 0.4],
                        [0.35, 0.05, 0.45], [0.3, 0.0, 0.5], [0.451, 0.05, 0.35]])
    figure = figures.build_tool_path(make_target_trace(tmp_path / "trace.npz", targets))
    texts, _ = drawn_labels(figure)
    assert texts == ["1", "2, 6", "3", "4", "5"]
    assert len(target_markers(figure.axes[0]).get_offsets()) == 6
    # the pure rule: within 2 % of the plot's extent shares a label, beyond it does not
    extent_m = 0.5
    near = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.0099]])
    far = near + np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0002]])
    spread_pt = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 50.0]])  # no label collisions
    labels = figures.choose_target_labels(near, spread_pt, extent_m)
    assert [label.text for label in labels] == ["1, 3", "2"]
    assert labels[0].numbers == (1, 3) and labels[0].position_m == (0.0, 0.0, 0.0)
    assert [label.text for label in figures.choose_target_labels(far, spread_pt, extent_m)] == [
        "1", "2", "3"]


def test_fig3_dense_trajectory_labels_do_not_collide(tmp_path: Path) -> None:
    s = np.linspace(0.0, 1.0, 36)  # 36 waypoints along a ~20 cm path, ~6 mm apart
    targets = np.stack([0.3 + 0.2 * s, 0.02 * np.sin(np.pi * s), 0.35 + 0.05 * s], axis=1)
    path = make_target_trace(tmp_path / "trace.npz", targets)
    figure = figures.build_tool_path(path)
    texts, anchors_pt = drawn_labels(figure)
    ax = figure.axes[0]
    assert len(target_markers(ax).get_offsets()) == 36  # every target keeps its marker
    assert texts[0].split(", ")[0] == "1" and texts[-1].split(", ")[-1] == "36"
    assert 2 <= len(texts) < 36
    numbers = [int(n) for text in texts for n in text.split(", ")]
    assert numbers == sorted(set(numbers))
    gaps_pt = [np.linalg.norm(a - b) for i, a in enumerate(anchors_pt) for b in anchors_pt[i + 1:]]
    # 0.5 pt: the layout engine settles the axes a fraction of a point further on a redraw
    assert min(gaps_pt) >= figures.LABEL_MIN_SEPARATION_PT - 0.5
    # the rendered text boxes, not only the anchors, stay apart
    renderer = figure.canvas.get_renderer()
    boxes = []
    for text in ax.texts:
        x, y, z = text.get_position_3d()
        xs, ys, _ = proj3d.proj_transform(x, y, z, ax.get_proj())
        text.set_position((xs, ys))
        boxes.append(text.get_window_extent(renderer))
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "targets, labelled by number (some omitted where crowded)" in legend
    # deterministic
    assert drawn_labels(figures.build_tool_path(path))[0] == texts


def test_fig3_sparse_targets_keep_every_label(tmp_path: Path) -> None:
    # 6 targets 10 cm apart, zig-zagging upwards
    targets = np.array([[0.3 + 0.1 * (i % 2), 0.0, 0.3 + 0.0866 * i] for i in range(6)])
    figure = figures.build_tool_path(make_target_trace(tmp_path / "trace.npz", targets))
    texts, _ = drawn_labels(figure)
    assert texts == ["1", "2", "3", "4", "5", "6"]
    legend = [t.get_text() for t in figure.axes[0].get_legend().get_texts()]
    assert legend[-1] == "targets, labelled by number"


def test_target_labels_first_and_last_kept_when_they_collide() -> None:
    # a closed loop on the page: the last target's label folds into the first's
    targets = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0], [0.05, 0.0, 0.0]])
    anchors_pt = np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 0.0], [3.0, 3.0]])
    labels = figures.choose_target_labels(targets, anchors_pt, extent_m=0.3)
    assert [label.text for label in labels] == ["1, 4", "2", "3"]
    assert figures.choose_target_labels(np.zeros((0, 3)), np.zeros((0, 2)), 1.0) == []
    with pytest.raises(ValueError, match="anchors"):
        figures.choose_target_labels(targets, anchors_pt[:2], 0.3)


@pytest.mark.slow
def test_trace_figures_written(trace_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    written = (figures.plot_kinematics(trace_file, out)
               + figures.plot_torques(trace_file, out, formats=("png",))
               + figures.plot_tool_path(trace_file, out, formats=("pdf",)))
    names = [path.name for path in written]
    assert names == ["fig5_kinematics_sac-seed0_rehab-reach-v0.png",
                     "fig5_kinematics_sac-seed0_rehab-reach-v0.pdf",
                     "fig6_torques_sac-seed0_rehab-reach-v0.png",
                     "fig3_tool_path_sac-seed0_rehab-reach-v0.pdf"]
    for path in written:
        (assert_png if path.suffix == ".png" else assert_pdf)(path)


def test_label_is_sanitised(tmp_path: Path) -> None:
    make_trace(tmp_path / "trace.npz", policy="my policy/v2:best", env_id="ns/odd env-v0")
    assert traces.load_trace(tmp_path / "trace.npz").label == "my-policy-v2-best_odd-env-v0"


# --------------------------------------------------------------------------- plot_all, errors


@pytest.mark.slow
def test_plot_all_calls_ensure_trace_for_model_without_trace(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "runs"
    with_model = make_run(root, "sac", 0, [1.0] * 30, model=True)
    make_run(root, "sac", 1, [2.0] * 30, model=True)
    make_trace(root / "rehab-reach-v0" / "sac" / "seed1" / "evaluation" / "trace.npz",
               policy="sac-seed1")
    calls: list[Path] = []

    def ensure_trace(run_dir: Path) -> Path:
        calls.append(Path(run_dir))
        target = Path(run_dir) / "evaluation" / "trace.npz"
        make_trace(target, policy="sac-seed0")
        return target

    fake = types.ModuleType("rehabbot.analysis.evaluation")
    fake.ensure_trace = ensure_trace  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "rehabbot.analysis.evaluation", fake)

    out = tmp_path / "figs"
    assert plotting.plot_all([root], out, evaluate=False, formats=("png",))
    assert calls == []
    written = plotting.plot_all([root], out, formats=("png",))
    assert calls == [with_model]
    names = sorted(path.name for path in written)
    assert names == sorted(["fig4_learning_curves.png"] + [
        f"fig{n}_{kind}_sac-seed{s}_rehab-reach-v0.png"
        for n, kind in ((3, "tool_path"), (5, "kinematics"), (6, "torques")) for s in (0, 1)])


@pytest.mark.slow
def test_plot_all_duplicate_labels_do_not_overwrite(tmp_path: Path) -> None:
    make_trace(tmp_path / "a" / "trace.npz")
    make_trace(tmp_path / "b" / "trace.npz")
    written = plotting.plot_all([tmp_path], tmp_path / "out", formats=("png",))
    assert sorted(path.name for path in written if path.name.startswith("fig6")) == [
        "fig6_torques_sac-seed0_rehab-reach-v0-2.png", "fig6_torques_sac-seed0_rehab-reach-v0.png"]


def test_missing_and_empty_dirs(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such file"):
        learning_curves.load_runs([tmp_path / "nope"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"empty: no training runs"):
        learning_curves.load_runs([tmp_path / "empty"])
    with pytest.raises(ValueError, match="no such file"):
        traces.find_traces([tmp_path / "nope"])


def test_corrupt_files_are_named(tmp_path: Path) -> None:
    run_dir = make_run(tmp_path / "csv", "ppo", 0, [1.0, 2.0])
    monitor = run_dir / "monitor" / "train_0.monitor.csv"
    monitor.write_text('#{"t_start": 0}\nr,l,t\n1.0,abc,0.1\n', encoding="utf-8")
    with pytest.raises(ValueError, match=r"train_0\.monitor\.csv: not a readable Monitor"):
        learning_curves.load_runs([tmp_path / "csv"])

    bad_manifest = make_run(tmp_path / "json", "ppo", 0, [1.0]) / "manifest.json"
    bad_manifest.write_text("{not json", encoding="utf-8")
    with pytest.raises(ValueError, match=r"manifest\.json is not a readable manifest"):
        learning_curves.load_runs([tmp_path / "json"])

    (tmp_path / "npz").mkdir()
    (tmp_path / "npz" / "trace.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match=r"trace\.npz: not a readable trace"):
        traces.load_trace(tmp_path / "npz" / "trace.npz")
    np.savez(tmp_path / "npz" / "trace.npz", time_s=np.zeros(3))
    with pytest.raises(ValueError, match="missing key"):
        traces.load_trace(tmp_path / "npz" / "trace.npz")

    make_trace(tmp_path / "short" / "trace.npz", duration_s=0.02)  # 2 samples: no jerk
    with pytest.raises(ValueError, match=r"short/trace\.npz: cannot differentiate"):
        figures.build_kinematics(tmp_path / "short" / "trace.npz")

    evals = make_run(tmp_path / "eval", "sac", 0, [1.0]) / "eval" / "evaluations.npz"
    evals.parent.mkdir()
    evals.write_bytes(b"garbage")
    with pytest.raises(ValueError, match=r"evaluations\.npz: not a readable"):
        learning_curves.build_learning_curves(learning_curves.load_runs([tmp_path / "eval"]),
                                              source="eval")


def test_missing_matplotlib_message(trace_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib.backends.backend_agg", None)
    with pytest.raises(ImportError, match=r'pip install "rehabbot\[plot\]"'):
        figures.build_torques(trace_file)


def test_bad_options() -> None:
    with pytest.raises(ValueError, match="source"):
        learning_curves.build_learning_curves([], source="test")
    with pytest.raises(ValueError, match="smooth"):
        learning_curves.build_learning_curves([], smooth=0)
    with pytest.raises(ValueError, match="format"):
        figures.save_figure(None, Path("."), "x", formats=("bmp",))  # type: ignore[arg-type]


# --------------------------------------------------------------------------- CLI


@pytest.mark.slow
def test_cmd_plot_writes_files(experiment: Path, trace_file: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    args = plot_parser().parse_args(["plot", str(experiment), "--smooth", "5",
                                     "--formats", "png", "--no-evaluate"])
    assert args.func is plot_cli.cmd_plot
    assert plot_cli.cmd_plot(args) == 0
    out = experiment / "figures"
    printed = capsys.readouterr().out.split()
    assert len(printed) == 4
    assert sorted(Path(p).name for p in printed) == sorted(
        ["fig4_learning_curves.png", "fig5_kinematics_sac-seed0_rehab-reach-v0.png",
         "fig6_torques_sac-seed0_rehab-reach-v0.png",
         "fig3_tool_path_sac-seed0_rehab-reach-v0.png"])
    for name in printed:
        assert Path(name).parent == out
        assert_png(Path(name))


def test_cmd_plot_errors(tmp_path: Path, trace_file: Path) -> None:
    parser = plot_parser()

    def run(*argv: str) -> CliError:
        with pytest.raises(CliError) as info:
            plot_cli.cmd_plot(parser.parse_args(["plot", *argv]))
        message = str(info.value)
        assert "\n" not in message
        return info.value

    err = run(str(tmp_path / "missing"))
    assert err.exit_code == EXIT_USAGE and "missing" in str(err)
    (tmp_path / "empty").mkdir()
    err = run(str(tmp_path / "empty"))
    assert err.exit_code == EXIT_USAGE and "empty" in str(err)

    (tmp_path / "a_file").write_text("x", encoding="utf-8")
    err = run(str(trace_file.parent), "--out", str(tmp_path / "a_file"))
    assert err.exit_code == EXIT_USAGE and "a_file" in str(err)
    err = run(str(trace_file.parent), "--out", str(tmp_path / "a_file" / "sub"))
    assert err.exit_code == EXIT_USAGE and "a_file" in str(err) and "not a folder" in str(err)
    err = run(str(trace_file.parent), "--out", str(tmp_path / "no" / "such" / "figs"))
    assert err.exit_code == EXIT_USAGE and "does not exist" in str(err)
    assert not (tmp_path / "no").exists()  # a user's --out is never built out of typos

    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "trace.npz").write_bytes(b"garbage")
    err = run(str(bad))
    assert err.exit_code == EXIT_FAILURE and "trace.npz" in str(err)

    for option, value in (("--smooth", "0"), ("--smooth", "1e26"), ("--smooth", "2000000"),
                          ("--dpi", "10"), ("--dpi", "100000"), ("--source", "test")):
        with pytest.raises(SystemExit):
            parser.parse_args(["plot", str(bad), option, value])


def test_plot_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        plot_parser().parse_args(["plot", "--help"])
    text = capsys.readouterr().out
    for needle in ("examples:", "rehabbot plot runs", "--no-evaluate", "--smooth", "Fig. 4",
                   "fig3_tool_path"):
        assert needle in text
