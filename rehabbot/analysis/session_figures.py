"""The figure of one episode of a deployment session (``rehabbot plot SESSION``: the folder
``rehabbot deploy`` wrote, its ``session.json`` or one ``episode-NNNN.npz``;
:mod:`rehabbot.deploy.session_log`). One figure per episode, ``session_<label>_ep<k>``:

=====================  ======================================================================
panel                  content
=====================  ======================================================================
one per robot joint    the joint measured in the simulator (solid) and, in shadow mode, on
                       the robot (dotted); the policy's command before the filter (dashed)
                       and the command sent after it (steps); each decision the filter did
                       not pass is a marker on the sent command, coloured by its action
cuff force             the force in the cuff [N] against its limit (dashed, with its value),
                       and the decisions the filter did not pass, as above
filter                 the running share of decisions the filter answered with each action
                       other than ``pass`` (clip, hold, back off, stop), each labelled with
                       its share over the episode: the hold fraction among them
tracking (shadow)      ``robot - simulator`` for every joint [rad]
=====================  ======================================================================

The title names the policy, the env, the backend, the episode and how it ended. Every line
carries a ``gid`` (:data:`SESSION_GIDS`, the markers ``intervention-<action>``) so that a
reader or a test finds it. matplotlib is imported only when a figure is built.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rehabbot.analysis.figures import (
    DEFAULT_FORMATS,
    DPI,
    LIMIT_COLOR,
    check_formats,
    legend_outside,
    new_figure,
    save_figure,
)
from rehabbot.analysis.traces import sanitize
from rehabbot.deploy.session_log import FILTER_ACTIONS, SessionEpisode, SessionLog, read_session
from rehabbot.envs.registration import env_short_name

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

SESSION_PREFIX = "session"
#: The ``gid`` of each kind of line: ``ax.get_lines()`` with ``line.get_gid() == ...``.
SESSION_GIDS = {"measured": "measured", "robot-measured": "robot-measured",
                "policy-command": "policy-command", "sent-command": "sent-command",
                "cuff-force": "cuff-force", "force-limit": "force-limit",
                "tracking-error": "tracking-error"}
ACTION_COLORS = {"clip": "#ff7f0e", "hold": "#9467bd", "back_off": "#8c564b",
                 "stop": LIMIT_COLOR}
ACTION_MARKERS = {"clip": "o", "hold": "s", "back_off": "v", "stop": "X"}
MEASURED_COLOR = "#1f77b4"
COMMAND_COLOR = "0.2"
POLICY_COLOR = "#2ca02c"


def intervention_gid(action: str) -> str:
    """The ``gid`` of the markers of decisions answered with ``action``."""
    return f"intervention-{action}"


def fraction_gid(action: str) -> str:
    """The ``gid`` of the running share of decisions answered with ``action``."""
    return f"filter-fraction-{action}"


def running_fraction(actions: np.ndarray, action: str) -> np.ndarray:
    """(T,) the share of decisions 0..k answered with ``action``, for each k."""
    hits = np.cumsum(np.asarray(actions) == action)
    return hits / np.arange(1, len(hits) + 1)


def _title(log: SessionLog, episode: SessionEpisode) -> str:
    header = log.header
    policy = (header.get("policy") or {}).get("spec") or (header.get("policy") or {}).get(
        "label", "policy")
    env = env_short_name(str(header.get("env_id", "env")))
    backend = header.get("backend", "?")
    mode = " (shadow mode)" if episode.shadow else ""
    return (f"Deployment: {policy} on {env}, backend {backend}{mode}\n"
            f"episode {int(episode['episode'])} (seed {int(episode['seed'])}), "
            f"{episode.decisions} decisions, ended: {episode.end}")


def _mark_interventions(ax: Axes, times: np.ndarray, values: np.ndarray,
                        actions: np.ndarray) -> None:
    for action in FILTER_ACTIONS[1:]:
        rows = np.flatnonzero(actions == action)
        if rows.size:
            ax.plot(times[rows], values[rows], linestyle="none",
                    marker=ACTION_MARKERS[action], markersize=5, color=ACTION_COLORS[action],
                    label=f"filter: {action.replace('_', ' ')}", gid=intervention_gid(action),
                    zorder=4)


def _joint_panel(ax: Axes, episode: SessionEpisode, j: int, name: str) -> None:
    time_s = np.asarray(episode["time_s"], dtype=float)
    decisions = episode.decisions
    times = time_s[:decisions]
    sent = np.asarray(episode["q_command_rad"], dtype=float)
    ax.plot(time_s, episode["q_rad"][:, j], color=MEASURED_COLOR, linewidth=1.4,
            label="measured (simulator)", gid=SESSION_GIDS["measured"])
    if episode.shadow:
        ax.plot(time_s, episode["robot_q_rad"][:, j], color="#17becf", linestyle=":",
                linewidth=1.6, label="measured (robot)", gid=SESSION_GIDS["robot-measured"])
    if decisions:
        ax.plot(times, episode["q_policy_rad"][:, j], color=POLICY_COLOR, linestyle="--",
                linewidth=1.0, label="policy's command", gid=SESSION_GIDS["policy-command"])
        ax.plot(times, sent[:, j], color=COMMAND_COLOR, linewidth=1.0, drawstyle="steps-post",
                label="sent (after the filter)", gid=SESSION_GIDS["sent-command"])
        _mark_interventions(ax, times, sent[:, j], episode["filter_action"])
    ax.set_title(name, fontsize="medium")
    ax.set_ylabel("[rad]")
    ax.grid(True, alpha=0.3)


def _force_panel(ax: Axes, episode: SessionEpisode) -> None:
    time_s = np.asarray(episode["time_s"], dtype=float)
    force = np.asarray(episode["cuff_force_n"], dtype=float)
    limit = float(episode["cuff_force_limit_n"])
    ax.plot(time_s, force, color=MEASURED_COLOR, linewidth=1.4, label="cuff force",
            gid=SESSION_GIDS["cuff-force"])
    if episode.shadow and np.any(np.isfinite(episode["robot_cuff_force_n"])):
        ax.plot(time_s, episode["robot_cuff_force_n"], color="#17becf", linestyle=":",
                linewidth=1.6, label="cuff force (robot's estimate)")
    ax.axhline(limit, color=LIMIT_COLOR, linestyle="--", linewidth=1.2,
               label=f"limit {limit:g} N", gid=SESSION_GIDS["force-limit"])
    decisions = episode.decisions
    if decisions:
        _mark_interventions(ax, time_s[:decisions], force[:decisions],
                            episode["filter_action"])
    top = float(np.nanmax(force, initial=0.0))
    ax.set_ylim(0.0, 1.1 * max(limit, top, 1e-3))
    ax.set_ylabel("cuff force [N]")
    ax.set_xlabel("time [s]")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)


def _filter_panel(ax: Axes, episode: SessionEpisode) -> None:
    decisions = episode.decisions
    times = np.asarray(episode["time_s"], dtype=float)[:decisions]
    actions = episode["filter_action"]
    shares = episode.intervention_fraction()
    for action in FILTER_ACTIONS[1:]:
        ax.plot(times, running_fraction(actions, action),
                color=ACTION_COLORS[action], linewidth=1.4,
                label=f"{action.replace('_', ' ')}: {100 * shares[action]:.1f}% of decisions",
                gid=fraction_gid(action))
    ax.set_ylim(0.0, 1.0)
    ax.set_ylabel("share of decisions\nso far")
    ax.set_xlabel("time [s]")
    ax.grid(True, alpha=0.3)
    legend_outside(ax, title="filter answered")


def build_session_episode(log: SessionLog, episode: SessionEpisode) -> Figure:
    """The figure of one episode (module docstring)."""
    names = [str(name) for name in episode["joint_names"]]
    n = len(names)
    cols = 2
    joint_rows = math.ceil(n / cols)
    extra = 3 if episode.shadow else 2
    figure = new_figure((12.0, 2.3 * (joint_rows + extra) + 0.8))
    grid = figure.add_gridspec(joint_rows + extra, cols)
    first: Axes | None = None
    for j, name in enumerate(names):
        ax = figure.add_subplot(grid[j // cols, j % cols], sharex=first)
        first = first or ax
        _joint_panel(ax, episode, j, name)
    if first is not None:
        legend_outside(first)
    row = joint_rows
    _force_panel(figure.add_subplot(grid[row, :], sharex=first), episode)
    _filter_panel(figure.add_subplot(grid[row + 1, :], sharex=first), episode)
    if episode.shadow:
        ax = figure.add_subplot(grid[row + 2, :], sharex=first)
        error = np.asarray(episode["tracking_error_rad"], dtype=float)
        for j, name in enumerate(names):
            ax.plot(episode["time_s"], error[:, j], linewidth=1.0, label=name,
                    gid=SESSION_GIDS["tracking-error"])
        ax.set_ylabel("robot - simulator\n[rad]")
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
        legend_outside(ax, title="tracking error")
    figure.suptitle(_title(log, episode))
    return figure


def session_stem(log: SessionLog, episode: SessionEpisode) -> str:
    """``session_<folder>_ep<k>``, safe as a file name."""
    return f"{SESSION_PREFIX}_{sanitize(log.label)}_ep{int(episode['episode']):04d}"


def plot_session(path: Path | str | SessionLog, out_dir: Path | str,
                 formats: Sequence[str] = DEFAULT_FORMATS, dpi: int = DPI) -> list[Path]:
    """Write the figure of every episode of the session at ``path`` (a folder, its
    ``session.json`` or one episode file) into ``out_dir``; returns the files written.

    Raises:
        DataError: no session there, or a damaged file (naming it).
        ValueError: a format that is not supported.
    """
    formats = check_formats(formats)
    log = path if isinstance(path, SessionLog) else read_session(path)
    written: list[Path] = []
    for episode in log.episodes:
        written += save_figure(build_session_episode(log, episode), out_dir,
                               session_stem(log, episode), formats, dpi)
    return written
