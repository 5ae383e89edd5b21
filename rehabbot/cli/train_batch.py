"""``rehabbot train ID --algo ppo --backend rsl_rl --num-envs N``: PPO on the batched env
(:mod:`rehabbot.rl.batch_training`), one run per seed."""

from __future__ import annotations

import argparse
import shlex
import signal
import sys
from pathlib import Path
from typing import Any

from rehabbot.cli.errors import EXIT_OK, CliError
from rehabbot.common.errors import UsageError
from rehabbot.common.signals import handling_signals
from rehabbot.envs.registration import env_short_name, resolve_env_id
from rehabbot.rl import runs

BATCH_BACKEND = "rsl_rl"
# Options of the CPU trainers that a batched run has no use for: (attribute, flag).
CPU_ONLY_OPTIONS = (("eval_freq", "--eval-freq"), ("eval_episodes", "--eval-episodes"),
                    ("demos", "--demos"), ("bc", "--bc"))


class SeedStop:
    """The SIGINT/SIGTERM handler of ``rehabbot train`` around its runs: it records the first
    signal, and the seed loop stops before the next seed. Each run latches signals itself
    (:mod:`rehabbot.rl.training`), says what it does with one, and hands one that came after
    its final save back here once the run is whole. A second signal raises
    KeyboardInterrupt at once."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self, signum: int, _frame: Any) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum


def _resume_command(args: argparse.Namespace, env_id: str, seeds: list[int],
                    total: int) -> str:
    limit = [] if args.time_limit_s is None else ["--time-limit-s", f"{args.time_limit_s:g}"]
    return shlex.join(["rehabbot", "train", env_short_name(env_id), "--algo", "ppo",
                       "--backend", BATCH_BACKEND, "--num-envs", str(args.n_envs),
                       "--timesteps", str(total), "--seeds", *map(str, seeds), *limit,
                       "--out", str(args.out), "--resume"])


def train_batched_cli(args: argparse.Namespace, default_seeds: tuple[int, ...],
                      env_kwargs: dict[str, Any] | None) -> int:
    """Train every seed of ``args`` on the batched env; 0 when done, 130/143 interrupted."""
    from rehabbot.rl.batch_training import (
        DEFAULT_NUM_ENVS,
        DEFAULT_TIMESTEPS,
        RslPpoSettings,
        read_settings,
        share_gpu_with_torch,
    )

    share_gpu_with_torch()  # JAX and PyTorch share the GPU here

    if args.algo.lower() != "ppo":
        raise UsageError(f"--backend {BATCH_BACKEND} trains PPO only, not {args.algo!r}")
    for attr, flag in CPU_ONLY_OPTIONS:
        if getattr(args, attr, None) not in (None, False):
            raise UsageError(f"{flag} is not used by --backend {BATCH_BACKEND} (evaluate the "
                             "run with `rehabbot evaluate RUN_DIR` on the CPU env)")
    if args.vec != "dummy":
        raise UsageError(f"--vec {args.vec}: --backend {BATCH_BACKEND} steps its worlds on "
                         "MuJoCo Warp, not in a Gymnasium vector env")
    env_id = resolve_env_id(args.env)
    settings = RslPpoSettings.from_mapping(read_settings(args.hyperparams, env_id))
    args.n_envs = args.n_envs or DEFAULT_NUM_ENVS
    seeds = list(args.seeds or default_seeds)
    total = args.timesteps or DEFAULT_TIMESTEPS
    kwargs = {} if args.checkpoint_freq is None else {"checkpoint_freq": args.checkpoint_freq}
    stop = SeedStop()
    with handling_signals(stop):
        return _train_seeds(args, env_id, seeds, total, settings, env_kwargs, kwargs, stop)


def _train_seeds(args: argparse.Namespace, env_id: str, seeds: list[int], total: int,
                 settings: Any, env_kwargs: dict[str, Any] | None, kwargs: dict[str, Any],
                 stop: SeedStop) -> int:
    from rehabbot.rl.batch_training import BatchRunPlan, BatchTrainingInterrupted, train_batched

    for index, seed in enumerate(seeds):
        if stop.signum is not None:
            left = seeds[index:]
            command = _resume_command(args, env_id, left, total)
            print(f"stopped by {signal.Signals(stop.signum).name} before seed {left[0]}: "
                  f"{len(left)} run{'s' if len(left) > 1 else ''} not trained; continue "
                  f"with: {command}", flush=True)
            return 128 + stop.signum
        plan = BatchRunPlan(env_id, seed=seed, total_timesteps=total, out_dir=Path(args.out),
                            num_envs=args.n_envs, env_kwargs=dict(env_kwargs or {}),
                            settings=settings, resume=args.resume, overwrite=args.overwrite,
                            time_limit_s=args.time_limit_s, **kwargs)
        print(f"{plan.run_dir}: {'resuming' if plan.resume else 'training'} ppo on {env_id} "
              f"({BATCH_BACKEND}, MuJoCo Warp), seed {seed}, to {total} steps ({plan.num_envs} "
              f"worlds, {plan.steps_per_iteration} steps per PPO iteration)", flush=True)

        def report(row: dict[str, Any]) -> None:
            if args.no_progress:
                return
            rate = row["success_rate"]
            success = "-" if rate is None else f"{100 * rate:.0f} %"
            print(f"  iteration {row['iteration']}: {row['timesteps']} steps, "
                  f"{row['episodes']} episodes ended, success {success}, "
                  f"{row['wall_clock_s']:.0f} s", flush=True)

        try:
            run_dir = train_batched(plan, report)
        except BatchTrainingInterrupted as err:
            command = _resume_command(args, env_id, seeds, total)
            print(f"{err.run_dir}: interrupted at {err.timesteps_done} steps, checkpoint "
                  f"{err.checkpoint}; resume with: {command}", flush=True)
            return err.exit_code
        except KeyboardInterrupt as err:
            raise CliError(f"{plan.run_dir}: interrupted before a checkpoint could be saved",
                           130) from err
        limit = args.time_limit_s
        ended = (f" at the {limit:g} s time limit" if limit is not None and
                 (runs.read_manifest(run_dir) or {}).get("stopped_by") == "time_limit" else "")
        print(f"{run_dir}: done{ended}; evaluate with: rehabbot evaluate {run_dir}", flush=True)
    if stop.signum is not None:  # after the last run had saved its final model
        print(f"received {signal.Signals(stop.signum).name} once the last run had saved its "
              "final model: every run is finished", file=sys.stderr, flush=True)
    return EXIT_OK
