"""How well the Franka backend tracks a joint trajectory, and how it stops, on franka-sim.

franka-sim (a server of the libfranka network protocol on MuJoCo, its own venv
``.venv-franka-sim``: ``tools/franka-sim-venv.sh``) is started on 127.0.0.1 with the FCI's
motion limits enforced (``rehabbot/deploy/franka_sim_server.py``: its offline FR3 model,
built from the URDF in the franka-sim wheel). :class:`rehabbot.deploy.franka.FrankaBackend`
connects with pylibfranka, and the script sends one target per control period (0.02 s, paced
by the robot's clock) of ``q0 + a (1 - cos(2 pi f t))`` on all seven joints for ``--seconds``
(a few tenths of a rad at 0.125-0.175 Hz, as in ``tests/test_franka_backend.py``), then calls
``stop()`` while the arm moves. Every 1 ms tick of the loop is recorded.

* **Tracking error**: per joint, the largest ``|q_measured(tick i) - setpoint(tick i - 1)|``
  over the run (the robot measures at a tick what the setpoint sent one tick before made of
  it), its 99th percentile and median. The setpoints themselves follow the targets one policy
  period plus half a period (the interpolation's delay) late and pass through every target
  exactly: ``tests/test_interpolation.py`` checks that on synthetic targets.
* **Stop**: the fastest joint speed when ``stop()`` was called, how long ``stop()`` took (the
  brake to rest, then the motion's end), and when the measured joint speeds fell below
  0.01 rad/s.
* **Link**: ticks the robot's clock skipped (a state arrived more than 1.5 ms after the
  previous one) and the playback rate the interpolation settled at (the caller's period over
  the robot's).

Timing depends on the machine's load (the server runs its 1 kHz physics loop in Python in
real time); the page records the machine. The script raises its scheduling priority where
allowed (root), as the test does.

Usage::

    python benchmarks/deploy/franka_tracking.py [--seconds 10] \\
        [--page docs/results/franka-tracking]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks.common.cli import add_page_argument, announce, script_command
from benchmarks.common.documents import (
    ROOT,
    make_document,
    make_table,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.deploy.franka_sim_server import NICENESS, SIM_PYTHON, franka_sim_server

sys.path.insert(0, str(ROOT / "tests"))
from test_franka_backend import command_paced, tracking_targets

REST_SPEED_RAD_S = 0.01
INTRO = """The Franka backend (`rehabbot.deploy.franka`, on pylibfranka) against franka-sim, a
server of the libfranka network protocol on MuJoCo run on this machine with the FCI's motion
limits enforced: one joint target every 20 ms on all seven joints, interpolated to the robot's
1 kHz loop by the backend, then a stop while the arm moves. The tracking error compares what
the robot measured at each 1 ms tick with the setpoint sent one tick before; the setpoints
themselves follow the targets 30 ms late (one policy period and the interpolation's delay)
and pass through each of them, which `tests/test_interpolation.py` checks on synthetic
targets. A simulator, not an FR3: see [the backends](../deployment/backends.md) for what is
untested against hardware."""


def run(seconds: float) -> dict[str, Any]:
    from rehabbot.deploy.franka import FrankaBackend

    with contextlib.suppress(PermissionError):
        os.setpriority(os.PRIO_PROCESS, 0, NICENESS)
    with tempfile.TemporaryDirectory() as folder, \
            franka_sim_server(Path(folder) / "server.log"):
        backend = FrankaBackend("127.0.0.1", record=True, watchdog_s=0.5)
        try:
            q0 = backend.state().q_rad
            steps = round(seconds / backend.control_dt_s)
            command_paced(backend, tracking_targets(q0, steps, backend.control_dt_s))
            healthy = backend.healthy()
            moving_rad_s = float(np.abs(backend.state().dq_rad_s).max())
            started = time.monotonic()
            backend.stop()
            stop_s = time.monotonic() - started
            rest_s = None
            while time.monotonic() - started < stop_s + 2.0:
                if np.abs(backend.state().dq_rad_s).max() < REST_SPEED_RAD_S:
                    rest_s = time.monotonic() - started
                    break
                time.sleep(0.002)
            trace = backend.trace()
            reason = backend.stop_reason
        finally:
            backend.close()
    error = np.abs(trace["q_rad"][1:] - trace["setpoint_rad"][:-1])
    gaps = np.diff(trace["time_s"])
    commands = np.diff(trace["command_time_s"])
    return {"healthy_until_stop": healthy, "stop_reason": reason, "ticks": len(trace["time_s"]),
            "robot_time_s": float(trace["time_s"][-1]), "commands": len(trace["command_time_s"]),
            "max_error_rad": error.max(axis=0).tolist(),
            "p99_error_rad": np.percentile(error, 99, axis=0).tolist(),
            "median_error_rad": np.median(error, axis=0).tolist(),
            "range_rad": np.ptp(trace["setpoint_rad"], axis=0).tolist(),
            "skipped_ticks": int((gaps > 0.0015).sum()),
            "mean_command_period_s": float(commands.mean()),
            "speed_at_stop_rad_s": moving_rad_s, "stop_s": stop_s, "rest_s": rest_s}


def tables(result: dict[str, Any]) -> list[dict[str, Any]]:
    joints = [f"joint{i}" for i in range(1, 8)]
    rows = [[joint, f"{span:.3f}", f"{mx * 1e3:.2f}", f"{p99 * 1e3:.2f}", f"{med * 1e3:.2f}"]
            for joint, span, mx, p99, med in zip(
                joints, result["range_rad"], result["max_error_rad"], result["p99_error_rad"],
                result["median_error_rad"], strict=True)]
    tracking = make_table(
        "tracking", "Tracking error per joint (measured at a tick against the setpoint of the "
        "tick before)", ["joint", "range moved [rad]", "max [mrad]", "99th percentile [mrad]",
                         "median [mrad]"], rows, align=["left", *["right"] * 4],
        note=f"{result['ticks']} ticks of 1 ms ({result['robot_time_s']:.2f} s of the robot's "
             f"clock), {result['commands']} targets; the tests require a max of 10 mrad.")
    rest = "not within 2 s" if result["rest_s"] is None else f"{result['rest_s']:.3f}"
    stop = make_table(
        "stop", "The stop and the link", ["quantity", "value"],
        [["healthy until the stop", "yes" if result["healthy_until_stop"] else "no"],
         ["fastest joint when stop() was called [rad/s]", f"{result['speed_at_stop_rad_s']:.3f}"],
         ["stop() returned after [s]", f"{result['stop_s']:.3f}"],
         ["joint speeds below 0.01 rad/s after [s]", rest],
         ["stop reason", result["stop_reason"]],
         ["ticks the robot's clock skipped", str(result["skipped_ticks"])],
         ["mean period between targets, robot's clock [ms]",
          f"{result['mean_command_period_s'] * 1e3:.2f}"]],
        align=["left", "right"])
    return [tracking, stop]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="length of the tracked trajectory (10)")
    add_page_argument(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.seconds > 0:
        parser.error(f"--seconds={args.seconds} must be positive")
    if not SIM_PYTHON.exists():
        parser.error(f"no franka-sim venv at {SIM_PYTHON.parent.parent}: run "
                     "tools/franka-sim-venv.sh first")
    result = run(args.seconds)
    command = script_command(__file__, argv)
    import pylibfranka

    machine = f"{describe_machine()}, pylibfranka {pylibfranka.__version__}, franka-sim 1.1.7"
    announce(command, machine)
    for table in tables(result):
        print(table_markdown(table))
    if args.page is not None:
        write_page(make_document(
            title="The Franka backend on franka-sim: tracking and stop", intro=INTRO,
            command=command, generated_by=__file__, tables=tables(result), machine=machine,
            settings={"seconds": args.seconds, "control_dt_s": 0.02, "watchdog_s": 0.5},
            data=result), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
