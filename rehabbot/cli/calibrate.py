"""``rehabbot calibrate ENV_ID --backend sim --out patient.json``: run the calibration
protocol on a robot, fit the patient's limb and write the patient that ``gym.make`` takes
(:mod:`rehabbot.deploy.calibration`); ``--from-log FILE`` fits a recorded session."""

from __future__ import annotations

import argparse
from pathlib import Path

from rehabbot.cli.errors import EXIT_OK, EXIT_USAGE, CliError, cli_command, env_kwargs_object

BACKENDS = ("sim",)

CALIBRATE_EPILOG = """\
examples:
  rehabbot calibrate rehab-knee-v2 --backend sim --out patient.json
  rehabbot calibrate rehab-reach-v2 --env-kwargs '{"condition": {"spasticity_mas": "2"}}' \\
      --noise-seed 0 --log session.npz --out patient.json
  rehabbot calibrate --from-log session.npz --height 1.68 --sex female --out patient.json

Then: gym.make(ENV_ID, **rehabbot.deploy.calibration.load_patient("patient.json")).
The protocol moves each calibrated joint slowly over its range and oscillates it a little
about two angles, at two postures of the other joint, then stretches it fast at two speeds
(docs/deployment/calibration.md)."""


@cli_command
def cmd_calibrate(args: argparse.Namespace) -> int:
    """Run or read a session, fit it and write the patient."""
    from rehabbot.common.files import check_parent_exists
    from rehabbot.deploy import calibration as cal
    from rehabbot.deploy.calibration_protocol import ProtocolSettings, Recording

    check_parent_exists(args.out)
    if args.log is not None:
        check_parent_exists(args.log, "--log")
    given = {key: value for key, value in (("height_m", args.height), ("mass_kg", args.mass),
                                           ("sex", args.sex)) if value is not None}
    if args.from_log is not None:
        recording = Recording.load(args.from_log)
        env_id = args.env_id or recording.env_id
        if not env_id:
            raise CliError(f"{args.from_log} names no env; give ENV_ID", EXIT_USAGE)
        backend = cal.simulator_backend(env_id, {**recording.env_kwargs,
                                                 **(args.env_kwargs or {})})
        result = cal.fit_recording(recording, backend.env.scene, given)
    else:
        if args.env_id is None:
            raise CliError("give ENV_ID (or --from-log FILE)", EXIT_USAGE)
        import numpy as np

        backend = cal.simulator_backend(args.env_id, args.env_kwargs)
        rng = None if args.noise_seed is None else np.random.default_rng(args.noise_seed)
        result = cal.calibrate(backend, backend.env.scene, joints=args.joints,
                               settings=ProtocolSettings(repetitions=args.repetitions),
                               given_profile=given, noise_rng=rng,
                               source=(args.env_id, {**cal.SIMULATOR_KWARGS,
                                                     **(args.env_kwargs or {})}))
        if args.log is not None:
            result.recording.save(args.log)
    cal.save_patient(args.out, result)
    fit = result.fit
    for name, joint in fit.joints.items():
        print(f"{name}: stiffness {joint.stiffness_nm_per_rad:.2f} N·m/rad, damping "
              f"{joint.damping_nms_per_rad:.2f} N·m·s/rad, inertia "
              f"{joint.inertia_kg_m2[0]:.3f} kg·m², VAF {100 * joint.vaf:.1f} %")
    stopped = result.recording.stopped_reason
    print(f"MAS {fit.spasticity_mas}, effort {fit.effort}"
          + (f" ({fit.effort_share:.2f} of healthy strength)" if fit.effort_share else "")
          + f"; {result.profile}" + (f"; session stopped: {stopped}" if stopped else ""))
    print(f"wrote {args.out}")
    return EXIT_OK


def add_calibrate_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser(
        "calibrate", help="measure a patient's limb on a robot and write the patient",
        description="Run the calibration protocol on a robot backend, fit the limb's "
                    "stiffness, damping,\ninertia, gravity, spasticity and effort, and write "
                    "the patient (profile and condition)\nthat gym.make takes.",
        epilog=CALIBRATE_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("env_id", metavar="ENV_ID", nargs="?",
                        help="a one-robot env id (its scene is the body model); with "
                             "--from-log, default: the log's")
    parser.add_argument("--backend", choices=BACKENDS, default="sim",
                        help="the robot (default sim: the env's own simulated patient)")
    parser.add_argument("--env-kwargs", type=env_kwargs_object, metavar="JSON",
                        help="env keyword arguments (the simulated patient: profile, "
                             "condition, robot, ...)")
    parser.add_argument("--out", type=Path, required=True, metavar="patient.json",
                        help="the patient file to write")
    parser.add_argument("--from-log", type=Path, metavar="FILE",
                        help="fit a session recorded with --log instead of running one")
    parser.add_argument("--log", type=Path, metavar="FILE.npz",
                        help="also write the session's recording")
    parser.add_argument("--joints", nargs="+", metavar="JOINT",
                        help="the joints to calibrate (default: every one the scene moves)")
    parser.add_argument("--repetitions", type=int, default=2,
                        help="repetitions of each ramp and stretch (default 2)")
    parser.add_argument("--noise-seed", type=int, metavar="SEED",
                        help="add sensor noise (encoders 1e-3 rad, force 1 N) drawn from "
                             "this seed before the fit (simulated sessions)")
    parser.add_argument("--height", type=float, metavar="M", help="the patient's height [m]")
    parser.add_argument("--mass", type=float, metavar="KG",
                        help="the patient's mass [kg] (default: from the fitted gravity)")
    parser.add_argument("--sex", choices=("male", "female"), help="the patient's sex")
    parser.set_defaults(func=cmd_calibrate)
