"""The main job (``make demo``, ``rehabbot demo``): train SAC with the library's own plain
network on ``rehabbot/rehab-knee-v2``, evaluate it against the scripted expert and random
actions, and write the paper's figures, a video and a summary.

Usage::

    rehabbot demo --out runs/demo [--timesteps 100000] [--demos 20] [--episodes 10] [--seed 0]

Steps, each with its output under ``OUT``:

1. ``rehabbot train rehab-knee-v2 --algo sac --demos 20`` (the shipped settings of ``-v2``:
   SBX's or SB3's own ``MlpPolicy``, 10-step returns; SBX when it is installed; 20
   scripted-expert episodes in the replay buffer first, without which the knee learns on
   some seeds only: ``docs/results/learning-v2.md``) →
   ``OUT/runs/rehab-knee-v2/sac/seed<k>/`` (model, checkpoints, monitor CSVs, TensorBoard
   logs, manifest). Interrupted (Ctrl-C)? Run the demo again: it resumes from the last
   checkpoint.
2. ``rehabbot evaluate`` of the trained model, the scripted expert and random actions on the
   same episode seeds → ``OUT/evaluation/<policy>/evaluation.json`` and ``trace.npz``.
3. ``rehabbot plot`` → ``OUT/figures/`` (Fig. 3 tool path, Fig. 4 learning curve, Fig. 5
   kinematics, Fig. 6 torques; PNG and PDF).
4. ``rehabbot render`` of one episode of the trained model → ``OUT/sac.mp4``.
5. ``OUT/summary.md`` and ``OUT/summary.json``: the comparison table, the wall-clock time of
   every step, and the commands that reproduce each step; the table is printed at the end.

The default budget (100 000 steps) trains in about 20 minutes on one CPU core (SBX) and ends
with an agent that finishes most episodes of the knee exercises (SBX's runs:
``docs/results/learning-v2.md``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rehabbot.cli import limits
from rehabbot.cli.errors import cli_command
from rehabbot.envs.registration import env_short_name

ENV_ID = "rehabbot/rehab-knee-v2"
ALGO = "sac"
DEFAULT_TIMESTEPS = 100_000
DEFAULT_DEMOS = 20  # scripted-expert episodes put into the replay buffer (--demos)
DEFAULT_EPISODES = 10
EVAL_SEED = 1000  # evaluation episodes use seeds the training never reset with
VIDEO_WIDTH_PX, VIDEO_HEIGHT_PX, VIDEO_FRAME_EVERY = 480, 360, 3  # 16.7 fps, software GL
HYPERPARAMS = "sac"  # rehabbot/rl/hyperparams/sac.yml: plain MlpPolicy for the -v2 ids
BACKEND = "auto"  # SBX (JAX) when installed (make demo installs it), else Stable-Baselines3
DEFAULT_OUT = Path("runs/demo")  # created with its parents; a user's --out needs its parent


def add_demo_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``demo`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser("demo", help="the main job: train SAC (plain network), evaluate, "
                                 "plot, render, summarise (make demo)",
                                 description=__doc__.split("\n\n")[0] + '\n\nNeeds pip '
                                 'install "rehabbot[train,plot,video]" ([video]: not with '
                                 "--no-video).",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help=f"output folder (default: {DEFAULT_OUT}); its parent folder must "
                             "exist")
    parser.add_argument("--timesteps", type=limits.timesteps, default=DEFAULT_TIMESTEPS,
                        metavar="N", help=f"SAC training steps (default: {DEFAULT_TIMESTEPS})")
    parser.add_argument("--demos", type=limits.demos, default=DEFAULT_DEMOS, metavar="N",
                        help=f"scripted-expert episodes put into the replay buffer before "
                        f"training (default: {DEFAULT_DEMOS})")
    parser.add_argument("--episodes", type=limits.episodes, default=DEFAULT_EPISODES,
                        metavar="N",
                        help=f"evaluation episodes per policy (default: {DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=limits.seed, default=0, metavar="S",
                        help=f"training seed (default: 0; 0 <= S <= {limits.MAX_SEED})")
    parser.add_argument("--hyperparams", default=HYPERPARAMS, metavar="FILE.yml|NAME",
                        help="SAC hyperparameters (default: sac, shipped with rehabbot)")
    parser.add_argument("--no-video", action="store_true", help="skip the video")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=cmd_demo)


@cli_command
def cmd_demo(args: argparse.Namespace) -> int:
    """Run the demo; an interrupted training says how to resume (run the demo again)."""
    from rehabbot.cli.needs import MP4_MODULES, NOTHING, PLOT_MODULES, TRAIN_MODULES, require
    from rehabbot.common.files import check_parent_exists

    require("rehabbot demo", TRAIN_MODULES, PLOT_MODULES, NOTHING if args.no_video else MP4_MODULES)
    if args.out is None:
        args.out = DEFAULT_OUT
    else:
        check_parent_exists(args.out)
    from rehabbot.rl.training import TrainingInterrupted

    try:
        return run_demo(args)
    except TrainingInterrupted as stop:
        print(f"rehabbot demo: training interrupted at {stop.timesteps_done} steps; a "
              f"checkpoint is saved in {stop.run_dir}. Run the demo again to resume.",
              flush=True)
        return stop.exit_code


def run_demo(args: argparse.Namespace) -> int:
    from rehabbot.analysis import evaluation, plotting, video
    from rehabbot.common.files import (
        atomic_write_json,
        atomic_write_text,
        check_output_file,
        check_writable_dir,
    )
    from rehabbot.rl import runs, training

    out: Path = args.out
    check_writable_dir(out)
    if not args.no_video:  # before training, not after it
        check_output_file(out / f"{ALGO}.mp4", video.VIDEO_SUFFIXES, "video")
        video.check_video_writer(out / f"{ALGO}.mp4")
    stages: dict[str, float] = {}
    commands: dict[str, str] = {}

    started = time.perf_counter()
    run_root = out / "runs"
    run_dir = runs.run_directory(run_root, ENV_ID, ALGO, args.seed)
    resume = (run_dir / runs.MANIFEST_NAME).is_file()
    demos = f", {args.demos} expert episodes in the replay buffer" if args.demos else ""
    print(f"[1/5] training SAC (the library's MlpPolicy) on {ENV_ID} for {args.timesteps} "
          f"steps{demos}"
          f"{' (resuming)' if resume else ''} -> {run_dir}", flush=True)
    training.train_run(ENV_ID, ALGO, args.seed, args.timesteps, run_root,
                       hyperparams=args.hyperparams, resume=resume,
                       progress_bar=not args.no_progress, backend=BACKEND,
                       demos=args.demos or None)
    stages["train"] = time.perf_counter() - started
    commands["train"] = (f"rehabbot train {env_short_name(ENV_ID)} --algo {ALGO} --timesteps "
                         f"{args.timesteps} --seeds {args.seed} --hyperparams {args.hyperparams}"
                         f"{f' --demos {args.demos}' if args.demos else ''} --out {run_root}")

    started = time.perf_counter()
    print(f"[2/5] evaluating SAC, the scripted expert and random actions on "
          f"{args.episodes} episodes (seeds {EVAL_SEED}..{EVAL_SEED + args.episodes - 1})",
          flush=True)
    reports = []
    model = str(run_dir / runs.MODEL_NAME)
    for report, trace in evaluation.evaluate_policies([model, "expert", "random"], ENV_ID,
                                                      args.episodes, EVAL_SEED):
        evaluation.save_report(report, trace, out / "evaluation" / report["policy"]["label"])
        reports.append(report)
    stages["evaluate"] = time.perf_counter() - started
    commands["evaluate"] = (f"rehabbot evaluate {model} expert random --episodes "
                            f"{args.episodes} --seed {EVAL_SEED} --out {out / 'evaluation'}")

    started = time.perf_counter()
    print("[3/5] plotting the paper's figures 3-6", flush=True)
    figures = plotting.plot_all([run_dir, out / "evaluation"], out / "figures", evaluate=False)
    stages["plot"] = time.perf_counter() - started
    commands["plot"] = (f"rehabbot plot {run_dir} {out / 'evaluation'} --out {out / 'figures'} "
                        "--no-evaluate")

    video_path = None
    if not args.no_video:
        started = time.perf_counter()
        video_path = out / f"{ALGO}.mp4"
        print(f"[4/5] rendering one SAC episode -> {video_path}", flush=True)
        video.render_episode(model, ENV_ID, video_path, seed=EVAL_SEED,
                             width=VIDEO_WIDTH_PX, height=VIDEO_HEIGHT_PX,
                             frame_every=VIDEO_FRAME_EVERY)
        stages["render"] = time.perf_counter() - started
        commands["render"] = (f"rehabbot render {model} --out {video_path} "
                              f"--seed {EVAL_SEED} --width {VIDEO_WIDTH_PX} --height "
                              f"{VIDEO_HEIGHT_PX} --frame-every {VIDEO_FRAME_EVERY}")

    print("[5/5] summary", flush=True)
    table = evaluation.format_table(reports)
    manifest = runs.read_manifest(run_dir) or {}
    summary = {
        "env_id": ENV_ID,
        "algo": ALGO,
        "train_seed": args.seed,
        "expert_episodes_in_buffer": args.demos,
        "train_timesteps": manifest.get("timesteps_done"),
        "train_wall_clock_s": manifest.get("wall_clock_s"),
        "eval_seeds": reports[0]["episode_seeds"],
        "stage_wall_clock_s": stages,
        "commands": commands,
        "results": {r["policy"]["label"]: r["summary"] for r in reports},
        "figures": [str(p) for p in figures],
        "video": str(video_path) if video_path else None,
    }
    atomic_write_json(out / "summary.json", summary)
    timing = ", ".join(f"{name} {seconds:.0f} s" for name, seconds in stages.items())
    text = (f"# RehabBot demo: SAC with a plain network on {ENV_ID}\n\n"
            f"SAC (the library's MlpPolicy, the shipped settings) trained "
            f"{summary['train_timesteps']} steps (seed {args.seed}"
            f"{f', {args.demos} expert episodes in its buffer' if args.demos else ''}); "
            "evaluated on "
            f"{args.episodes} episodes with seeds {EVAL_SEED}..{EVAL_SEED + args.episodes - 1}"
            f" (mean ± std over episodes).\n\n{table}\n\nWall clock: {timing}.\n\n"
            "Reproduce each step:\n\n"
            + "\n".join(f"    {command}" for command in commands.values()) + "\n")
    atomic_write_text(out / "summary.md", text)
    print()
    print(text)
    print(f"figures: {out / 'figures'}; video: {video_path}; summary: {out / 'summary.md'}")
    return 0
