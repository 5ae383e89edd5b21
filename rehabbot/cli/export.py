"""``rehabbot export POLICY --format onnx --out FILE``: a trained policy (a zoo agent, a run
folder or a model zip) as one ONNX file for a robot PC, with what the robot needs to run it
in its metadata (:mod:`rehabbot.rl.onnx_export`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from rehabbot.cli.errors import EXIT_OK, cli_command

ONNX_MODULES = {"onnx": "onnx", "onnxruntime": "onnx"}

EXPORT_EPILOG = """\
examples:
  rehabbot export zoo:rehab-knee-v2/sac --out knee-sac.onnx
  rehabbot export zoo:rehab-hip-v2/ppo-fr3 --format onnx --out hip-ppo-fr3.onnx
  rehabbot export runs/rehab-knee-v2/sac/seed0 --out knee-sac-seed0.onnx
  rehabbot export model.zip --env rehab-knee-v2 --out knee.onnx   # a zip outside a run

The file holds one float32 graph, input "observation" (batch, obs_dim), output "action"
(batch, act_dim): the run's observation normalisation, the actor, its deterministic head
(tanh / clip) and the action unscale, checked against the policy before it is written (at
most 1e-5 apart). Its metadata (JSON values) names the env and kwargs, the control rate, every
observation entry, the action bounds, the robot and its joints, the control mode, the cuff
force limits and the patient's range of motion. Load it with
rehabbot.rl.onnx_export.load_onnx_policy, or with onnxruntime alone in Python or C++
(docs/deployment/export.md). Needs pip install "rehabbot[onnx]" (and, for a model zip, the
library it was trained with: [train] or [jax])."""


@cli_command
def cmd_export(args: argparse.Namespace) -> int:
    """Export the policy and say what was written."""
    from rehabbot.cli.needs import policy_modules, require
    from rehabbot.common.files import check_parent_exists
    from rehabbot.rl.onnx_export import export_onnx

    check_parent_exists(args.out)
    require(f"rehabbot export --format {args.format}", ONNX_MODULES,
            policy_modules(args.policy))
    meta = export_onnx(args.policy, args.out, env_id=args.env, format=args.format)
    print(f"wrote {args.out}: {meta['source']} for {meta['env_id']} "
          f"({meta['robot']}, {meta['control_mode']}), {len(meta['observation_names'])} "
          f"observations -> {len(meta['action_low'])} actions at "
          f"{meta['control_rate_hz']:g} Hz; weights sha256 {meta['weights_sha256'][:12]}")
    return EXIT_OK


def add_export_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``export`` to the ``rehabbot`` subcommands."""
    from rehabbot.rl.onnx_export import FORMATS

    parser = commands.add_parser(
        "export", help="a trained policy as one ONNX file for a robot PC",
        description="Export a trained policy's deterministic actor, with its observation "
                    "scaling and action bounds,\nto one ONNX file for onnxruntime.",
        epilog=EXPORT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policy", metavar="POLICY",
                        help="zoo:ENV/AGENT (a shipped agent: `rehabbot zoo list`), a "
                             "`rehabbot train` run folder, or a model .zip")
    parser.add_argument("--format", choices=FORMATS, default=FORMATS[0],
                        help=f"the file format (default {FORMATS[0]})")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.onnx",
                        help="the file to write, in an existing folder (replaced atomically)")
    parser.add_argument("--env", metavar="ID",
                        help="the env of a model zip outside a run folder (a run folder's "
                             "manifest and a zoo agent name their own)")
    parser.set_defaults(func=cmd_export)
