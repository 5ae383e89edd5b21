"""The main job (``make demo``): train SAC on ``rehabbot/rehab-reach-v0``, evaluate it against
the scripted expert and random actions, and write the paper's figures, a video and a summary.

Usage::

    python -m rehabbot.demo --out runs/demo [--timesteps 40000] [--episodes 10] [--seed 0]

Steps, each with its output under ``OUT``:

1. ``rehabbot train rehab-reach-v0 --algo sac`` with ``hyperparams/sac.yml`` (the settings
   of the README's results) → ``OUT/runs/rehab-reach-v0/sac/seed<k>/`` (model, checkpoints,
   monitor CSVs, TensorBoard logs, manifest). Interrupted (Ctrl-C)? Run the demo again: it
   resumes from the last checkpoint.
2. ``rehabbot evaluate`` of the trained model, the scripted expert and random actions on the
   same episode seeds → ``OUT/evaluation/<policy>/evaluation.json`` and ``trace.npz``.
3. ``rehabbot plot`` → ``OUT/figures/`` (Fig. 3 tool path, Fig. 4 learning curve, Fig. 5
   kinematics, Fig. 6 torques; PNG and PDF).
4. ``rehabbot render`` of one episode of the trained model → ``OUT/sac.mp4``.
5. ``OUT/summary.md`` and ``OUT/summary.json``: the comparison table, the wall-clock time of
   every step, and the commands that reproduce each step; the table is printed at the end.

The default budget (40 000 steps) finishes within 15 minutes on 2 CPU cores; it is a
demonstration of the pipeline, not a converged policy (see the README's results table for
that: ``rehabbot train rehab-reach-v0 --algo sac --timesteps 200000``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from rehabbot.cli import use_headless_gl_by_default

ENV_ID = "rehabbot/rehab-reach-v0"
ALGO = "sac"
DEFAULT_TIMESTEPS = 40_000
DEFAULT_EPISODES = 10
EVAL_SEED = 1000  # evaluation episodes use seeds the training never reset with
VIDEO_WIDTH_PX, VIDEO_HEIGHT_PX, VIDEO_FRAME_EVERY = 480, 360, 3  # 16.7 fps, software GL
HYPERPARAMS = Path(__file__).resolve().parent.parent / "hyperparams" / "sac.yml"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m rehabbot.demo",
                                     description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/demo"), metavar="DIR",
                        help="output folder (default: runs/demo)")
    parser.add_argument("--timesteps", type=int, default=DEFAULT_TIMESTEPS, metavar="N",
                        help=f"SAC training steps (default: {DEFAULT_TIMESTEPS})")
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, metavar="N",
                        help=f"evaluation episodes per policy (default: {DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="training seed (0)")
    parser.add_argument("--hyperparams", type=Path, default=HYPERPARAMS, metavar="FILE.yaml",
                        help="SAC hyperparameters (default: hyperparams/sac.yml)")
    parser.add_argument("--no-video", action="store_true", help="skip the video")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    use_headless_gl_by_default()
    args = build_parser().parse_args(argv)
    from rehabbot.policies import PolicyError
    from rehabbot.training import TrainingError, TrainingInterrupted

    try:
        return run(args)
    except TrainingInterrupted as stop:
        print(f"rehabbot demo: training interrupted at {stop.timesteps_done} steps; a "
              f"checkpoint is saved in {stop.run_dir}. Run the demo again to resume.",
              file=sys.stderr)
        return stop.exit_code
    except (TrainingError, PolicyError, OSError) as err:
        print(f"rehabbot demo: error: {' '.join(str(err).split())}", file=sys.stderr)
        return getattr(err, "exit_code", 1)


def run(args: argparse.Namespace) -> int:
    from rehabbot import evaluation, plotting, training, video

    out: Path = args.out
    evaluation.check_writable(out)
    stages: dict[str, float] = {}
    commands: dict[str, str] = {}

    started = time.perf_counter()
    run_root = out / "runs"
    run_dir = training.run_directory(run_root, ENV_ID, ALGO, args.seed)
    resume = (run_dir / "manifest.json").is_file()
    print(f"[1/5] training SAC on {ENV_ID} for {args.timesteps} steps"
          f"{' (resuming)' if resume else ''} -> {run_dir}", flush=True)
    training.train_run(ENV_ID, ALGO, args.seed, args.timesteps, run_root,
                       hyperparams=args.hyperparams, resume=resume,
                       progress_bar=not args.no_progress)
    stages["train"] = time.perf_counter() - started
    commands["train"] = (f"rehabbot train {training.env_short_name(ENV_ID)} --algo sac --timesteps "
                         f"{args.timesteps} --seeds {args.seed} --hyperparams {args.hyperparams}"
                         f" --out {run_root}")
    commands["train"] = commands["train"].replace(str(HYPERPARAMS), _relative(HYPERPARAMS))

    started = time.perf_counter()
    print(f"[2/5] evaluating SAC, the scripted expert and random actions on "
          f"{args.episodes} episodes (seeds {EVAL_SEED}..{EVAL_SEED + args.episodes - 1})",
          flush=True)
    reports = []
    for spec in (str(run_dir / "model.zip"), "expert", "random"):
        report, trace = evaluation.evaluate(spec, ENV_ID, args.episodes, EVAL_SEED)
        evaluation.save_report(report, trace, out / "evaluation" / report["policy"]["label"])
        reports.append(report)
    stages["evaluate"] = time.perf_counter() - started
    commands["evaluate"] = (f"rehabbot evaluate {run_dir / 'model.zip'} expert random --env "
                            f"{training.env_short_name(ENV_ID)} --episodes {args.episodes} --seed "
                            f"{EVAL_SEED} --out {out / 'evaluation'}")

    started = time.perf_counter()
    print("[3/5] plotting the paper's figures 3-6", flush=True)
    figures = plotting.plot_all([run_dir, out / "evaluation"], out / "figures", evaluate=False)
    stages["plot"] = time.perf_counter() - started
    commands["plot"] = (f"rehabbot plot {run_dir} {out / 'evaluation'} --out {out / 'figures'} "
                        "--no-evaluate")

    video_path = None
    if not args.no_video:
        started = time.perf_counter()
        video_path = out / "sac.mp4"
        print(f"[4/5] rendering one SAC episode -> {video_path}", flush=True)
        video.render_episode(str(run_dir / "model.zip"), ENV_ID, video_path, seed=EVAL_SEED,
                             width=VIDEO_WIDTH_PX, height=VIDEO_HEIGHT_PX,
                             frame_every=VIDEO_FRAME_EVERY)
        stages["render"] = time.perf_counter() - started
        commands["render"] = (f"rehabbot render {run_dir / 'model.zip'} --out {video_path} "
                              f"--seed {EVAL_SEED} --width {VIDEO_WIDTH_PX} --height "
                              f"{VIDEO_HEIGHT_PX} --frame-every {VIDEO_FRAME_EVERY}")

    print("[5/5] summary", flush=True)
    table = evaluation.format_table(reports)
    manifest = json.loads((run_dir / "manifest.json").read_text())
    summary = {
        "env_id": ENV_ID,
        "algo": ALGO,
        "train_seed": args.seed,
        "train_timesteps": manifest.get("timesteps_done"),
        "train_wall_clock_s": manifest.get("wall_clock_s"),
        "eval_seeds": reports[0]["episode_seeds"],
        "stage_wall_clock_s": stages,
        "commands": commands,
        "results": {r["policy"]["label"]: r["summary"] for r in reports},
        "figures": [str(p) for p in figures],
        "video": str(video_path) if video_path else None,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    timing = ", ".join(f"{name} {seconds:.0f} s" for name, seconds in stages.items())
    text = (f"# RehabBot demo: SAC on {ENV_ID}\n\n"
            f"SAC trained {summary['train_timesteps']} steps (seed {args.seed}); evaluated on "
            f"{args.episodes} episodes with seeds {EVAL_SEED}..{EVAL_SEED + args.episodes - 1}"
            f" (mean ± std over episodes).\n\n{table}\n\nWall clock: {timing}.\n\n"
            "Reproduce each step:\n\n"
            + "\n".join(f"    {command}" for command in commands.values()) + "\n")
    (out / "summary.md").write_text(text)
    print()
    print(text)
    print(f"figures: {out / 'figures'}; video: {video_path}; summary: {out / 'summary.md'}")
    return 0


def _relative(path: Path) -> str:
    """``path`` relative to the working folder when it is inside it (shorter commands)."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


if __name__ == "__main__":
    sys.exit(main())
