"""``rehabbot deploy POLICY --backend sim|franka|ur --out DIR``: a policy through the
deployment safety filter on a robot, every decision logged (:mod:`rehabbot.deploy.session`);
``rehabbot plot DIR`` draws the session."""

from __future__ import annotations

import argparse
import json
import shlex
from pathlib import Path

from rehabbot.cli.errors import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    bounded_float,
    bounded_int,
    cli_command,
    env_kwargs_object,
)

MAX_EPISODES = 100_000
MAX_SEED = 2**31 - 1

DEPLOY_EPILOG = """\
examples:
  rehabbot deploy zoo:rehab-knee-v2/ppo --backend sim --episodes 3 --out sessions/knee
  rehabbot deploy expert --env rehab-reach-v2 --backend sim --out sessions/expert
  rehabbot deploy policy.onnx --backend sim --filter-config '{"hold_fraction": 0.8}' \\
      --out sessions/onnx
  rehabbot deploy zoo:rehab-hip-v2/ppo-fr3 --backend franka --robot-ip 172.16.0.2 \\
      --filter-config filter.json --out sessions/fr3
  rehabbot plot sessions/knee                       # the session's figures

POLICY: zoo:ENV/AGENT, a `rehabbot train` run folder or model.zip, 'expert' (with --env),
or an ONNX file written by `rehabbot export`. Each decision: the policy's action becomes
joint targets, the safety filter passes, clips, holds, backs off or stops them, and the
result is sent. On --backend sim the simulator is the robot. On franka or ur the robot runs
in shadow mode: the simulator (the twin) computes the policy's observation, a filter checks
each command against the twin's state and a second one against the robot's measured state,
and the command goes to both; before each episode the robot is moved to the twin's start
pose. The twin's patient is a model, not the person in the chair (docs/deployment/session.md).

--filter-config: a JSON object (or a .json file holding one) of the filter's settings, e.g.
max_speed_rad_s, max_accel_rad_s2, hold_fraction, back_off_fraction, rom_margin_rad,
cuff_force_limit_n; the rest comes from the env (its decision period, setpoint box, the
patient's range of motion and cuff force limit; by default the caps are the fastest the env
lets a policy move).

DIR gets session.json and one episode-NNNN.npz per episode, each written when its episode
ends; Ctrl-C stops the robot and closes the log (exit 130). A session that the filter or a
fault stopped exits 1; a folder holding a session is refused (exit 2)."""


def add_deploy_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``deploy`` to the ``rehabbot`` subcommands."""
    from rehabbot.deploy.backend import BACKENDS

    parser = commands.add_parser(
        "deploy", help="run a policy through the deployment safety filter on the simulator "
                       "or a robot, and log the session",
        description="Deploy a policy: the safety filter between it and a robot, every "
                    "decision logged.",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=DEPLOY_EPILOG)
    parser.add_argument("policy", metavar="POLICY",
                        help="zoo:ENV/AGENT, a run folder or model.zip, 'expert', or a .onnx file")
    parser.add_argument("--backend", choices=BACKENDS, required=True,
                        help="sim: the simulator; franka, ur: a real robot (shadow mode)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="the session folder (its parent folder must exist)")
    parser.add_argument("--robot-ip", metavar="IP", help="the robot's address (franka, ur)")
    parser.add_argument("--filter-config", metavar="JSON",
                        help="the filter's settings: a JSON object, or a .json file")
    parser.add_argument("--episodes", type=bounded_int(1, MAX_EPISODES), default=1,
                        metavar="N", help=f"episodes, 1 to {MAX_EPISODES:,} (default: 1)")
    parser.add_argument("--seed", type=bounded_int(0, MAX_SEED), default=0, metavar="S",
                        help="episode k is reset with seed S + k (default: 0)")
    parser.add_argument("--env", metavar="ENV",
                        help="env id (default: the one the policy was trained on; required "
                             "for expert)")
    parser.add_argument("--env-kwargs", type=env_kwargs_object, default=None, metavar="JSON",
                        help="env keyword arguments on top of the policy's, e.g. "
                             "'{\"weight_level\": 3}'")
    parser.add_argument("--approach-speed", type=bounded_float(0.0, 1.0, low_open=True),
                        default=0.2, metavar="RAD_S",
                        help="joint speed of the move to each episode's start pose "
                             "(franka, ur), at most 1 (default: 0.2 rad/s)")
    parser.add_argument("--robot-watchdog", type=bounded_float(0.0, 1.0, low_open=True),
                        default=None, metavar="S",
                        help="the robot's servo loop brakes to rest when no target came for "
                             "this long (franka, ur; default: the backend's, 0.1 s)")
    parser.set_defaults(func=cmd_deploy)


def filter_settings(text: str | None) -> dict | None:
    """``--filter-config``: a JSON object, or the path of a ``.json`` file holding one.

    Raises:
        CliError: (exit 2) not JSON, not an object, or a file that cannot be read.
    """
    if text is None:
        return None
    source = "--filter-config"
    if text.lstrip()[:1] not in ("{", "["):
        path = Path(text)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as err:
            raise CliError(f"--filter-config {str(path)!r}: neither a JSON object nor a "
                           f"readable file ({err.strerror or err})", EXIT_USAGE) from err
        source = f"--filter-config file {str(path)!r}"
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise CliError(f"{source}: not valid JSON ({err})", EXIT_USAGE) from err
    if not isinstance(value, dict):
        raise CliError(f"{source}: must be a JSON object, got {type(value).__name__}",
                       EXIT_USAGE)
    return value


@cli_command
def cmd_deploy(args: argparse.Namespace) -> int:
    """Run ``rehabbot deploy``: the session, its summary, the ``rehabbot plot`` line."""
    from rehabbot.cli.needs import policy_modules, require
    from rehabbot.cli.threads import one_torch_thread
    from rehabbot.deploy.launch import deploy
    from rehabbot.deploy.session import SessionSettings

    if args.backend == "sim" and args.robot_ip is not None:
        raise CliError("--robot-ip is for --backend franka or ur", EXIT_USAGE)
    settings = filter_settings(args.filter_config)
    robot_modules = {"franka": {"pylibfranka": "franka"},
                     "ur": {"rtde_control": "ur", "rtde_receive": "ur"}}.get(args.backend, {})
    require("rehabbot deploy", policy_modules(args.policy), robot_modules)
    one_torch_thread([args.policy])
    result = deploy(args.policy, args.out, args.backend, episodes=args.episodes,
                    seed=args.seed, env_id=args.env, env_kwargs=args.env_kwargs,
                    filter_settings=settings, robot_ip=args.robot_ip,
                    settings=SessionSettings(approach_speed_rad_s=args.approach_speed),
                    robot_watchdog_s=args.robot_watchdog)
    for line in result.episodes:
        actions = ", ".join(f"{k} {v}" for k, v in line["filter_actions"].items())
        print(f"episode {line['episode']} (seed {line['seed']}): {line['decisions']} "
              f"decisions, ended {line['end']}, success {line['success']}, return "
              f"{line['return']:.2f}; filter: {actions or 'no decisions'}")
    print(f"session log: {args.out} ({result.status})")
    print(f"its figures: rehabbot plot {shlex.quote(str(args.out))}")
    if result.status != "completed":
        raise CliError(f"the session {result.status}: {result.reason}", EXIT_FAILURE)
    return EXIT_OK
