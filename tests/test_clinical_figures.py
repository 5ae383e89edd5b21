"""Figures a therapist can read out of their folder: the patient and condition in every title,
every limit line with its value and source, legends off the data, safety stops marked, work
labelled as cumulative with its sign explained, the controllers of one evaluation overlaid, a
range of motion beyond the prescription flagged; and the clinical-evaluation page shows
Figs. 7-10, made by a command of the repository and small."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("matplotlib")

import rehabbot  # noqa: F401
from rehabbot.analysis import figures, patient_figures, plotting
from rehabbot.analysis.evaluation import format_table, summarize
from rehabbot.analysis.patient_records import format_patient_table
from rehabbot.analysis.recorder import patient_limits
from rehabbot.analysis.traces import load_trace

REPO = Path(__file__).resolve().parent.parent
ENV_ID = "rehabbot/rehab-hip-v2"
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
MAS3 = "male, 1.75 m, 75 kg; MAS 3 spasticity"
HEALTHY = "male, 1.75 m, 75 kg; healthy, passive"
FORCE_SOURCE = "ISO/TS 15066 quasi-static, lower legs"
ROM_SOURCE = "AAOS normal range; stop 2° beyond"
TORQUE_SOURCE = "UR5e rated joint torque, Universal Robots"


def write_trace(path: Path, policy: str = "aan", patient: str | None = MAS3,
                stop: str = "", seed: int = 0, force_peak_n: float = 90.0,
                hip_excursion_deg: float = 30.0) -> Path:
    """A hip trace as ``rehabbot evaluate`` writes it: 4 s at 50 Hz; the hip flexes by
    ``hip_excursion_deg`` towards targets 20 degrees out, the cuff force rises to
    ``force_peak_n`` at the end (over the 130 N limit when it is larger)."""
    t = np.arange(0.0, 4.0, 0.02)
    n = len(t)
    ramp = t / t[-1]
    hip = np.radians(5.0 + hip_excursion_deg * np.sin(np.pi * ramp / 2))
    patient_qpos = np.column_stack([hip, np.full(n, np.radians(5.0)), np.full(n, 0.17)])
    data = {
        "env_id": np.array(ENV_ID), "policy": np.array(policy), "seed": np.array(seed),
        "dt_s": np.array(0.02), "time_s": t,
        "robot_qpos_rad": 0.3 * np.sin(np.pi * ramp)[:, None] * np.ones((1, 6)),
        "robot_torque_nm": 20.0 * np.cos(np.pi * ramp)[:, None] * np.ones((1, 6)),
        "torque_limit_nm": np.array([150, 150, 150, 28, 28, 28.0]),
        "joint_names": np.array(JOINTS),
        "tool_pos_m": np.column_stack([0.4 + 0.1 * ramp, 0.05 * ramp, 0.3 + 0.1 * ramp]),
        "target_tool_pos_m": np.array([[0.45, 0.02, 0.35], [0.5, 0.05, 0.4]]),
        "target_robot_rad": np.zeros((2, 6)),
        "target_index": (ramp > 0.5).astype(int),
        "patient_qpos_rad": patient_qpos,
        "interaction_force_n": 60.0 + (force_peak_n - 60.0) * ramp**4,
        "target_patient_deg": np.array([[15.0, 5.0, 10.0], [25.0, 5.0, 10.0]]),
        "patient_joint_names": np.array(["hip_flexion_r", "hip_abduction_r", "knee_flexion_r"]),
        "patient_range_deg": np.array([[-30.0, 120.0], [-30.0, 45.0], [0.0, 135.0]]),
        "cuff_force_limit_n": np.array(130.0),
        "robot_work_j": 10.0 * np.sin(np.pi * ramp),
        "patient_work_j": -0.5 * ramp,
        "safety_violation": np.array(stop),
        "robot_name": np.array("ur5e"),
        "torque_limit_source": np.array(TORQUE_SOURCE),
        "cuff_force_limit_source": np.array(FORCE_SOURCE),
        "patient_range_source": np.array(ROM_SOURCE),
    }
    if patient is not None:
        data["patient"] = np.array(patient)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **data)
    return path


TRACE_FIGURES = {
    "fig3": figures.build_tool_path, "fig5": figures.build_kinematics,
    "fig6": figures.build_torques, "fig7": patient_figures.build_patient_joints,
    "fig8": patient_figures.build_cuff_force, "fig9": patient_figures.build_work,
}


def lines_by_gid(ax, gid: str) -> list:
    return [line for line in ax.get_lines() if line.get_gid() == gid]


def legends(figure) -> list:
    found = [ax.get_legend() for ax in figure.axes if ax.get_legend() is not None]
    return found + list(figure.legends)


# ------------------------------------------------------------------ the patient in every title
@pytest.mark.parametrize("name", sorted(TRACE_FIGURES))
def test_every_title_names_the_patient_and_condition(tmp_path, name) -> None:
    build = TRACE_FIGURES[name]
    mas3 = build(write_trace(tmp_path / "a" / "trace.npz", patient=MAS3))
    healthy = build(write_trace(tmp_path / "b" / "trace.npz", patient=HEALTHY))
    assert f"patient: {MAS3}" in mas3.get_suptitle()
    assert f"patient: {HEALTHY}" in healthy.get_suptitle()
    assert "aan on rehab-hip-v2" in mas3.get_suptitle()
    older = build(write_trace(tmp_path / "c" / "trace.npz", patient=None))
    assert "patient: not recorded" in older.get_suptitle()


def test_the_evaluator_records_the_patient_and_every_limit_source() -> None:
    from rehabbot.analysis.evaluation import evaluate_policies

    short = {"max_episode_steps": 20}
    (report, trace), = evaluate_policies(
        ["expert"], "rehab-hip-v2", episodes=1,
        env_kwargs={**short, "condition": {"spasticity_mas": "3"}})
    assert str(trace["patient"]) == MAS3
    assert report["per_episode"][0]["patient"]["description"] == MAS3
    assert str(trace["cuff_force_limit_source"]) == FORCE_SOURCE
    assert float(trace["cuff_force_limit_n"]) == 130.0
    assert str(trace["patient_range_source"]) == ROM_SOURCE
    assert str(trace["torque_limit_source"]) == TORQUE_SOURCE
    assert str(trace["safety_violation"]) == ""
    (_report, healthy), = evaluate_policies(["expert"], "rehab-hip-v2", episodes=1,
                                            env_kwargs=short)
    assert str(healthy["patient"]) == HEALTHY


@pytest.mark.parametrize("env_id, kwargs, expected", [
    ("rehabbot/rehab-reach-v2", {}, {
        "cuff_force_limit_n": 140.0,
        "cuff_force_limit_source": "ISO/TS 15066 quasi-static, hands and fingers",
        "torque_limit_source": TORQUE_SOURCE}),
    ("rehabbot/rehab-hip-v2", {"robot": "fr3"}, {
        "cuff_force_limit_n": 130.0,
        "torque_limit_source": "Franka 'Limits for Franka Research 3'"}),
    ("rehabbot/rehab-reach-v2", {"cuff_force_limit_n": 100.0,
                                 "condition": {"rom_scale": 0.8}}, {
        "cuff_force_limit_n": 100.0, "cuff_force_limit_source": "the env's cuff_force_limit_n",
        "patient_range_source": "AAOS normal range x 0.8 (condition's rom_scale); stop 2° "
                                "beyond"}),
])
def test_each_limit_names_where_it_comes_from(env_id, kwargs, expected) -> None:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    limits = patient_limits(env)
    env.close()
    for key, value in expected.items():
        assert limits[key].item() == value, key


@pytest.mark.parametrize("condition, text", [
    (None, "healthy, passive"),
    ({"spasticity_mas": "3"}, "MAS 3 spasticity"),
    ({"spasticity_mas": "2", "stiffness_scale": 1.5, "rom_scale": 0.8},
     "MAS 2 spasticity, stiffness x1.5, ROM x0.8"),
    ({"effort": "active_assisted", "strength_fraction": 0.5},
     "active-assisted (effort 30 %), strength 50 %"),
    ({"tremor_hz": 5.0, "tremor_amplitude_nm": 2.0}, "tremor 5 Hz, 2 N·m"),
])
def test_conditions_read_as_a_therapist_words_them(condition, text) -> None:
    from rehabbot.analysis.patient_records import condition_text
    from rehabbot.sim.conditions import PatientCondition

    fields = None if condition is None else PatientCondition(**condition).to_dict()
    assert condition_text(fields) == text


# ------------------------------------------------------------------ limits with value and source
def test_limit_lines_carry_their_value_and_source(tmp_path) -> None:
    path = write_trace(tmp_path / "trace.npz")
    torques = figures.build_torques(path)
    for ax, limit in zip(torques.axes, (150, 150, 150, 28, 28, 28), strict=True):
        labels = {line.get_label() for line in lines_by_gid(ax, "torque-limit")}
        assert f"limit ±{limit} N·m\n({TORQUE_SOURCE})" in labels
    force_ax = patient_figures.build_cuff_force(path).axes[0]
    limit, = lines_by_gid(force_ax, "force-limit")
    assert limit.get_label() == f"limit 130 N\n({FORCE_SOURCE})"
    joints = patient_figures.build_patient_joints(path)
    for ax, (low, high) in zip(joints.axes, ((-30, 120), (-30, 45), (0, 135)), strict=True):
        rom, = lines_by_gid(ax, "rom-low")
        assert rom.get_label() == f"range of motion {low}° to {high}°\n({ROM_SOURCE})"
        assert len(lines_by_gid(ax, "rom-high")) == 1


# ------------------------------------------------------------------ legends off the data
@pytest.mark.parametrize("name", sorted(TRACE_FIGURES))
def test_legends_sit_outside_every_axes(tmp_path, name) -> None:
    figure = TRACE_FIGURES[name](write_trace(tmp_path / "trace.npz", stop="cuff_force",
                                             force_peak_n=140.0))
    figure.draw_without_rendering()
    renderer = figure.canvas.get_renderer()
    found = legends(figure)
    assert found
    for legend in found:
        box = legend.get_window_extent(renderer)
        for ax in figure.axes:
            if ax.get_visible():
                assert not box.overlaps(ax.get_window_extent(renderer)), (name, legend)


def test_the_force_limit_crossing_is_marked_and_never_under_the_legend(tmp_path) -> None:
    path = write_trace(tmp_path / "trace.npz", stop="cuff_force", force_peak_n=140.0)
    trace = load_trace(path)
    figure = patient_figures.build_cuff_force(trace)
    ax = figure.axes[0]
    crossing, = lines_by_gid(ax, "limit-crossing")
    first = int(np.flatnonzero(trace.interaction_force_n > 130.0)[0])
    assert crossing.get_xdata()[0] == trace.time_s[first]
    assert f"above the limit from {trace.time_s[first]:.2f} s" in crossing.get_label()
    figure.draw_without_rendering()
    point = ax.transData.transform((trace.time_s[first], trace.interaction_force_n[first]))
    assert not ax.get_legend().get_window_extent().contains(*point)
    below = patient_figures.build_cuff_force(write_trace(tmp_path / "b" / "trace.npz"))
    assert not lines_by_gid(below.axes[0], "limit-crossing")


# ------------------------------------------------------------------ safety stops marked
@pytest.mark.parametrize("name", ["fig5", "fig6", "fig7", "fig8", "fig9"])
def test_a_safety_stop_is_marked_with_its_rule_on_every_time_axis(tmp_path, name) -> None:
    build = TRACE_FIGURES[name]
    trace = load_trace(write_trace(tmp_path / "trace.npz", stop="cuff_force",
                                   force_peak_n=140.0))
    figure = build(trace)
    for ax in (ax for ax in figure.axes if ax.get_visible()):
        stop, = lines_by_gid(ax, "safety-stop")
        assert stop.get_xdata()[0] == trace.time_s[-1]
    labels = [text.get_text() for legend in legends(figure) for text in legend.get_texts()]
    assert f"safety stop: cuff_force rule at {trace.time_s[-1]:.2f} s" in labels
    unstopped = build(write_trace(tmp_path / "b" / "trace.npz"))
    assert not any(lines_by_gid(ax, "safety-stop") for ax in unstopped.axes)


def test_the_tool_path_marks_where_the_episode_stopped(tmp_path) -> None:
    trace = load_trace(write_trace(tmp_path / "trace.npz", stop="range_of_motion"))
    ax = figures.build_tool_path(trace).axes[0]
    marker, = [c for c in ax.collections if c.get_gid() == "safety-stop"]
    assert marker.get_label().startswith("safety stop: range_of_motion rule")
    np.testing.assert_allclose(np.ravel(marker._offsets3d), trace.tool_pos_m[-1])


# ------------------------------------------------------------------ work labelled
def test_work_is_labelled_cumulative_with_its_sign_explained(tmp_path) -> None:
    figure = patient_figures.build_work(write_trace(tmp_path / "trace.npz"))
    ax = figure.axes[0]
    assert "cumulative" in ax.get_ylabel() and "[J]" in ax.get_ylabel()
    assert figure.get_suptitle().startswith("Cumulative work on the limb since the start")
    note = ax.get_legend().get_title().get_text()
    assert "work > 0: puts energy into the limb" in note and "work < 0: takes energy out" in note
    robot, = lines_by_gid(ax, "robot-work")
    assert robot.get_label() == "robot, through the cuff (end: +0.00 J)"


# ------------------------------------------------------------------ the controllers overlaid
def test_the_overlay_draws_one_line_per_controller_in_every_panel(tmp_path) -> None:
    from rehabbot.analysis.overlay_figure import build_overlay

    paths = [write_trace(tmp_path / label / "trace.npz", policy=label,
                         stop="cuff_force" if label == "random" else "",
                         force_peak_n=140.0 if label == "random" else 90.0)
             for label in ("expert", "aan", "random")]
    figure = build_overlay(paths)
    axes = figure.axes
    assert len(axes) == 3  # the one exercised joint, cuff force, robot work
    for ax in axes:
        policies = [line.get_gid() for line in ax.get_lines()
                    if (line.get_gid() or "").startswith("policy:")]
        assert policies == ["policy:expert", "policy:aan", "policy:random"]
        assert len(lines_by_gid(ax, "safety-stop")) == 1  # random's stop
    assert f"patient: {MAS3}" in figure.get_suptitle() and "seed 0" in figure.get_suptitle()
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert "random: safety stop, cuff_force rule" in labels
    assert f"cuff force limit 130 N\n({FORCE_SOURCE})" in labels
    figure.draw_without_rendering()
    box = figure.legends[0].get_window_extent()
    assert not any(box.overlaps(ax.get_window_extent()) for ax in axes)
    other = write_trace(tmp_path / "other" / "trace.npz", policy="other", seed=5)
    with pytest.raises(ValueError, match="not the same episode"):
        build_overlay([paths[0], other])


@pytest.mark.slow
def test_plot_draws_one_overlay_per_evaluation_folder(tmp_path) -> None:
    from rehabbot.analysis.overlay_figure import overlay_groups

    for label in ("expert", "aan"):
        write_trace(tmp_path / "ev" / label / "trace.npz", policy=label)
    write_trace(tmp_path / "alone" / "random" / "trace.npz", policy="random")
    assert len(overlay_groups([load_trace(p) for p in sorted(tmp_path.rglob("trace.npz"))])) == 1
    written = plotting.plot_all([tmp_path], tmp_path / "figs", formats=("png",))
    names = {path.name for path in written}
    assert "fig10_overlay_rehab-hip-v2.png" in names
    assert {f"fig{n}_{kind}_{label}_rehab-hip-v2.png" for n, kind in (
        (7, "patient_joints"), (8, "cuff_force"), (9, "work"))
        for label in ("expert", "aan", "random")} <= names
    written = plotting.plot_all([tmp_path], tmp_path / "nopatient", formats=("png",),
                                patient=False)
    assert not any(path.name.startswith(("fig7", "fig10")) for path in written)


# ------------------------------------------------------------------ a range beyond the prescription
def test_a_range_of_motion_beyond_the_prescription_is_flagged_in_the_figure(tmp_path) -> None:
    # the hip moves 29.2 degrees where the path prescribes 20 (5 -> 15 -> 25): 1.46
    figure = patient_figures.build_patient_joints(
        write_trace(tmp_path / "a" / "trace.npz", hip_excursion_deg=29.2))
    hip = figure.axes[0]
    assert hip.get_title() == ("hip_flexion_r: achieved 29° of 20° prescribed (1.46) "
                                         "⚠ beyond the prescribed range")
    assert hip.title.get_color() == figures.LIMIT_COLOR
    assert figure.axes[1].get_title().startswith("hip_abduction_r: not exercised")
    within = patient_figures.build_patient_joints(
        write_trace(tmp_path / "b" / "trace.npz", hip_excursion_deg=19.0))
    assert within.axes[0].get_title() == ("hip_flexion_r: achieved 19° of 20° "
                                                    "prescribed (0.95)")


def _report(label: str, fractions: list[float]) -> dict:
    episodes = [{"seed": k, "success": True, "return": 1.0, "length": 10,
                 "steps_to_finish": 10, "safety_violation": None, "truncated": False,
                 "peak_cuff_force_n": 50.0, "peak_torque_per_joint_nm": [1.0] * 6,
                 "rom_achieved_fraction": fraction,
                 "patient": {"description": MAS3, "index": k}}
                for k, fraction in enumerate(fractions)]
    from rehabbot.analysis.patient_records import per_patient_summary

    return {"policy": {"label": label}, "summary": summarize(episodes),
            "episode_seeds": [e["seed"] for e in episodes],
            "per_patient": per_patient_summary(episodes)}


def test_a_range_of_motion_beyond_the_prescription_is_flagged_in_the_tables() -> None:
    beyond, within = _report("aan", [1.44, 1.48]), _report("expert", [0.95, 0.96])
    rows = {line.split("|")[1].strip(): line for line in
            format_table([beyond, within]).splitlines()}
    row = [cell.strip() for cell in rows["ROM achieved / prescribed"].split("|")[2:4]]
    assert row == ["1.46 ± 0.02 ⚠ beyond the prescribed range", "0.955 ± 0.005"]
    assert "⚠ beyond the prescribed range" in format_patient_table(beyond)
    assert "⚠" not in format_patient_table(within)


# ------------------------------------------------------------------ the page shows Figs. 7-10
def test_the_clinical_page_shows_figs_7_to_10_made_by_a_command_and_small() -> None:
    page = (REPO / "docs" / "clinical-evaluation.md").read_text(encoding="utf-8")
    images = re.findall(r"!\[[^\]]+\]\(([^)]+\.png)\)", page)
    shown = {Path(image).name.split("_")[0] for image in images}
    assert {"fig7", "fig8", "fig9", "fig10"} <= shown, images
    for image in images:
        path = (REPO / "docs" / image).resolve()
        assert path.is_file(), image
        assert path.stat().st_size <= 150_000, (image, path.stat().st_size)
    script = "benchmarks/results/clinical_figures.py"
    assert script in page and (REPO / script).is_file()
    made = (REPO / script).read_text(encoding="utf-8")
    for image in images:
        assert Path(image).name.split("_")[0] in made
