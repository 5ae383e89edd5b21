"""The main job (``make demo``, ``rehabbot demo``): train PPO with a behaviour-cloned start on
``rehabbot/rehab-reach-v1``, evaluate it against the scripted expert and random actions, and
write the paper's figures, a video and a summary.

Usage::

    rehabbot demo --out runs/demo [--timesteps 100000] [--demos 40] [--episodes 10] [--seed 0]

Steps, each with its output under ``OUT``:

1. ``rehabbot train rehab-reach-v1 --algo ppo --hyperparams ppo --backend sb3 --bc --demos 40``
   (the settings of the README's ``-v1`` results, shipped with the package, on
   Stable-Baselines3 as measured there): PPO's actor is first cloned from 40 scripted-expert
   episodes, then trained on the ``-v1`` reward → ``OUT/runs/rehab-reach-v1/ppo/seed<k>/``
   (model, checkpoints, monitor CSVs, TensorBoard logs, manifest). Interrupted (Ctrl-C)? Run
   the demo again: it resumes from the last checkpoint.
2. ``rehabbot evaluate`` of the trained model, the scripted expert and random actions on the
   same episode seeds → ``OUT/evaluation/<policy>/evaluation.json`` and ``trace.npz``.
3. ``rehabbot plot`` → ``OUT/figures/`` (Fig. 3 tool path, Fig. 4 learning curve, Fig. 5
   kinematics, Fig. 6 torques; PNG and PDF).
4. ``rehabbot render`` of one episode of the trained model → ``OUT/ppo.mp4``.
5. ``OUT/summary.md`` and ``OUT/summary.json``: the comparison table, the wall-clock time of
   every step, and the commands that reproduce each step; the table is printed at the end.

The default budget (100 000 steps) trains in about 6 minutes on one CPU core and ends with an
agent that finishes most episodes (the README's Quickstart has the measured table). Before
0.3.0 the demo trained SAC on ``rehab-reach-v0``, whose reward traps agents short of the
targets (README, "Results"): it ended with a 0 % agent.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rehabbot.cli.errors import cli_command, non_negative_int
from rehabbot.envs.registration import env_short_name

ENV_ID = "rehabbot/rehab-reach-v1"
ALGO = "ppo"
DEFAULT_TIMESTEPS = 100_000
DEFAULT_DEMOS = 40  # scripted-expert episodes cloned into PPO's actor (--bc)
DEFAULT_EPISODES = 10
EVAL_SEED = 1000  # evaluation episodes use seeds the training never reset with
VIDEO_WIDTH_PX, VIDEO_HEIGHT_PX, VIDEO_FRAME_EVERY = 480, 360, 3  # 16.7 fps, software GL
HYPERPARAMS = "ppo"  # rehabbot/rl/hyperparams/ppo.yml
BACKEND = "sb3"  # the README's -v1 results are Stable-Baselines3's (TrackingErrorFeatures)


def add_demo_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``demo`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser("demo", help="the main job: train PPO (cloned start), evaluate, "
                                 "plot, render, summarise (make demo)",
                                 description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/demo"), metavar="DIR",
                        help="output folder (default: runs/demo)")
    parser.add_argument("--timesteps", type=int, default=DEFAULT_TIMESTEPS, metavar="N",
                        help=f"PPO training steps, in whole rollouts of 2048 (default: "
                        f"{DEFAULT_TIMESTEPS})")
    parser.add_argument("--demos", type=int, default=DEFAULT_DEMOS, metavar="N",
                        help=f"expert episodes cloned into PPO's actor before training "
                        f"(default: {DEFAULT_DEMOS})")
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, metavar="N",
                        help=f"evaluation episodes per policy (default: {DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=non_negative_int, default=0, metavar="S",
                        help="training seed (default: 0; S >= 0)")
    parser.add_argument("--hyperparams", default=HYPERPARAMS, metavar="FILE.yml|NAME",
                        help="PPO hyperparameters (default: ppo, shipped with rehabbot)")
    parser.add_argument("--no-video", action="store_true", help="skip the video")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=cmd_demo)


@cli_command
def cmd_demo(args: argparse.Namespace) -> int:
    """Run the demo; an interrupted training says how to resume (run the demo again)."""
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
    print(f"[1/5] cloning {args.demos} expert episodes into PPO's actor, then training PPO on "
          f"{ENV_ID} for {args.timesteps} steps"
          f"{' (resuming)' if resume else ''} -> {run_dir}", flush=True)
    training.train_run(ENV_ID, ALGO, args.seed, args.timesteps, run_root,
                       hyperparams=args.hyperparams, resume=resume,
                       progress_bar=not args.no_progress, backend=BACKEND,
                       demos=args.demos, bc=True)
    stages["train"] = time.perf_counter() - started
    commands["train"] = (f"rehabbot train {env_short_name(ENV_ID)} --algo {ALGO} --timesteps "
                         f"{args.timesteps} --seeds {args.seed} --hyperparams {args.hyperparams}"
                         f" --backend {BACKEND} --bc --demos {args.demos} --out {run_root}")

    started = time.perf_counter()
    print(f"[2/5] evaluating PPO, the scripted expert and random actions on "
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
        print(f"[4/5] rendering one PPO episode -> {video_path}", flush=True)
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
        "bc_expert_episodes": args.demos,
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
    text = (f"# RehabBot demo: PPO (behaviour-cloned start) on {ENV_ID}\n\n"
            f"PPO cloned {args.demos} expert episodes, then trained "
            f"{summary['train_timesteps']} steps (seed {args.seed}); evaluated on "
            f"{args.episodes} episodes with seeds {EVAL_SEED}..{EVAL_SEED + args.episodes - 1}"
            f" (mean ± std over episodes).\n\n{table}\n\nWall clock: {timing}.\n\n"
            "Reproduce each step:\n\n"
            + "\n".join(f"    {command}" for command in commands.values()) + "\n")
    atomic_write_text(out / "summary.md", text)
    print()
    print(text)
    print(f"figures: {out / 'figures'}; video: {video_path}; summary: {out / 'summary.md'}")
    return 0
