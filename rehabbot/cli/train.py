"""``rehabbot train``: parse the arguments, plan every seed's run, train them one after the
other (:mod:`rehabbot.rl.training`), print a summary line per run and the command that
resumes an interrupted one."""

from __future__ import annotations

import argparse
import shlex
import signal
import sys
from collections.abc import Sequence
from typing import Any

from rehabbot.cli import limits
from rehabbot.cli.errors import EXIT_OK, EXIT_USAGE, CliError, cli_command, env_kwargs_object
from rehabbot.cli.help_levels import add_help_levels
from rehabbot.cli.train_batch import BATCH_BACKEND, SeedStop, train_batched_cli
from rehabbot.envs.registration import env_short_name
from rehabbot.rl.algorithms import ALGORITHMS, OFF_POLICY
from rehabbot.rl.backends import BACKEND_CHOICES, DEFAULT_BACKEND
from rehabbot.rl.hyperparams import (
    library_defaults,
    settings_names,
    settings_path,
    shipped_settings,
)
from rehabbot.rl.planning import (
    DEFAULT_BC_EPISODES,
    DEFAULT_CHECKPOINT_FREQ,
    DEFAULT_EVAL_EPISODES,
    DEFAULT_EVAL_FREQ,
    DEFAULT_TIMESTEPS,
    SHIPPED_DEMOS,
    VEC_ENV_KINDS,
)

DEFAULT_SEEDS = (0,)
DEFAULT_OUT = "runs"


def parse_env_kwargs(text: str | None) -> dict[str, Any] | None:
    """``--env-kwargs`` as a dict (None if not given); :class:`CliError` (usage) otherwise."""
    if text is None:
        return None
    try:  # the checks of evaluate's and render's --env-kwargs (render_mode included)
        return env_kwargs_object(text)
    except argparse.ArgumentTypeError as err:
        raise CliError(f"--env-kwargs: {err}", EXIT_USAGE) from None


# What `rehabbot train --help` shows; `--help-all` shows every option and TRAIN_EPILOG.
ESSENTIAL_OPTIONS = ("env", "algo", "timesteps", "seeds", "out", "resume", "overwrite",
                     "backend")

TRAIN_BRIEF_EPILOG = """\
examples:
  rehabbot train rehab-reach-v2 --algo sac            # the shipped settings (printed)
  rehabbot train rehab-knee-v2 --algo td3 --timesteps 500000 --seeds 0 1 2
  rehabbot train rehab-reach-v2 --algo sac --timesteps 400000 --resume   # continue a run

Each seed writes OUT/<env>/<algo>/seed<k>/: manifest.json, checkpoints/, logs and, at the
end, model.zip. Ctrl-C saves a checkpoint and prints the command that resumes. Needs
pip install "rehabbot[train]"; with "rehabbot[jax]" too, --backend auto trains on SBX (JAX).

--help-all: every option (settings files, env kwargs, expert episodes, parallel and batched
envs, checkpoints, evaluation) and the details of each.

exit codes: 0 done, 1 runtime failure, 2 bad usage, 130/143 interrupted (resumable)."""

TRAIN_EPILOG = """\
examples:
  rehabbot train rehab-reach-v2 --algo sac            # the shipped settings (printed)
  rehabbot train rehabbot/rehab-knee-v2 --algo td3 --timesteps 500000 --seeds 0 1 2
  rehabbot train rehab-hip-v2 --algo ppo --vec subproc --out runs/ppo-sweep
  rehabbot train rehab-reach-v2 --algo sac --env-kwargs '{"weight_level": 2}'
  rehabbot train rehab-reach-v2 --algo sac --timesteps 400000 --resume   # continue a run
  rehabbot train rehab-knee-v2 --algo sac --demos 0   # no expert episodes in the buffer
  rehabbot train rehab-reach-v2 --algo ppo --bc --demos 50  # a behaviour-cloned start
  rehabbot train rehab-reach-v0 --algo sac --hyperparams sb3-defaults/sac  # the paper's id,
      # the library's defaults

Settings. Without --hyperparams a run uses the settings file shipped for the algorithm (sac,
td3, ppo, tqc, crossq in rehabbot/rl/hyperparams/), its entry for the id, and prints which; an
off-policy run then also starts with 20 scripted-expert episodes in its replay buffer, as the
published results did (--demos N changes that). The files hold entries for the -v2 ids, which
name only library options (MlpPolicy, n_steps, ...). The -v0 ids (the paper's reference: its
reward traps agents) and the -v1 ids observe the paper's fields, from which a plain network
does not learn: without --hyperparams they are refused with the -v2 id to train instead;
--hyperparams sb3-defaults/<algo> trains any id with the library's defaults. A run too short
to update its model (PPO: fewer steps than one rollout, n_steps x n_envs; SAC/TD3/TQC/CrossQ:
no more steps than learning_starts) is refused.

Run folders. Each seed writes OUT/<env>/<algo>/seed<k>/ with manifest.json,
monitor/train_<i>.monitor.csv, eval/evaluations.npz, tb/ (tensorboard --logdir OUT),
checkpoints/ and, at the end, model.zip. OUT's parent folder must exist. Ctrl+C (or SIGTERM)
saves a checkpoint and prints the command that resumes; exit code 130 (143 for SIGTERM). A
signal that comes once a run has saved its final model lets that run finish: the command
then stops before the next seed (130/143), or exits 0 when no seed is left. --resume
continues every seed from its newest checkpoint to --timesteps (default: the total it was
started with); settings come from the run's manifest. Off-policy checkpoints keep the replay
buffer of the newest checkpoint only (it can take hundreds of MB). Runs end at exactly N
steps with one env (an off-policy algorithm collects train_freq steps at a time, so it may
run up to train_freq - 1 steps past N); PPO does not train on a last, partial rollout.

Backends. --backend auto (the default) trains on SBX (JAX; pip install "rehabbot[jax]") when
it is installed and on Stable-Baselines3 (PyTorch; pip install "rehabbot[train]", which every
backend but rsl_rl needs) otherwise; sb3 or sbx force one. TQC and CrossQ come from
sb3-contrib on sb3. A settings file is read for SBX with what only PyTorch runs translated or
dropped (a PyTorch policy class becomes SBX's MlpPolicy, features extractors are dropped,
nn.ReLU becomes flax.linen.relu, ...): each change is printed and listed in the manifest
(hyperparameters.backend_changes). A resumed or evaluated run uses the backend it was
trained with (manifest.json: backend, backend_version).

Batched. --backend rsl_rl trains rsl_rl's PPO on the batched env (MuJoCo Warp; pip install
"rehabbot[gpu]"; a GPU makes it fast), e.g.
  rehabbot train rehab-reach-v2 --algo ppo --backend rsl_rl --num-envs 4096
It writes the same run folder (the actor as policy.npz, which `rehabbot evaluate RUN_DIR` runs
on the CPU env); --hyperparams takes a YAML mapping of its settings (docs/batch.md);
--time-limit-s S ends each run after the first PPO iteration past S seconds of wall clock.

Hyperparameter files are RL-Zoo-style YAML: env ids (full or short) mapped to hyperparameters,
or one flat mapping. Keys: the SB3 constructor arguments of the algorithm, plus n_timesteps,
n_envs, policy, normalize (true or VecNormalize arguments), noise_type (normal |
ornstein-uhlenbeck) and noise_std (SAC/TD3). policy_kwargs may be a mapping or a string such
as "dict(net_arch=[64, 64], activation_fn=nn.ReLU)"; learning_rate may be "lin_3e-4" (linear
decay to 0). policy is MlpPolicy or a library's policy class by dotted name (rehabbot's own
network classes, rehabbot.rl.features.*, are refused by name). --hyperparams takes a path or
the name of a file shipped with rehabbot: sac, td3, ppo, tqc and crossq hold the settings of
the -v2 ids, sb3-defaults/<algo> spells out SB3's defaults as a template, ablations/<name>
the plain-network diagnoses of the README (listed under --hyperparams above; the files are in
rehabbot/rl/hyperparams/).

""" + f"""
Bounds: seeds in [0, {limits.MAX_SEED:,}]; step counts up to {limits.MAX_TIMESTEPS:,};
--n-envs up to {limits.MAX_N_ENVS:,}; --eval-episodes up to {limits.MAX_EPISODES:,}; --demos up to
{limits.MAX_DEMOS:,}; --time-limit-s up to {limits.MAX_TIME_LIMIT_S:g} s.

exit codes: 0 done, 1 runtime failure (a missing extra included), 2 bad usage, 130/143
interrupted (resumable)."""


def add_train_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``train`` subcommand (``func=cmd_train``) to ``commands``: ``--help`` shows
    the essential options, ``--help-all`` every one, grouped."""
    parser = commands.add_parser(
        "train",
        help="train an agent (PPO, SAC, TD3, TQC, CrossQ) with SBX or Stable-Baselines3",
        description="Train an agent on a RehabBot env with SBX (JAX) or Stable-Baselines3 "
                    "(PyTorch),\none run per seed, with checkpoints, evaluation, TensorBoard "
                    "logs and a manifest.",
        epilog=TRAIN_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        add_help=False,
    )
    add_help_levels(parser, ESSENTIAL_OPTIONS, TRAIN_BRIEF_EPILOG)
    run = parser.add_argument_group("what to train")
    run.add_argument("env", metavar="ENV",
                     help="env id, with or without 'rehabbot/' (`rehabbot list` shows them)")
    run.add_argument("--algo", required=True, metavar="{" + ",".join(ALGORITHMS) + "}",
                     help="the algorithm")
    run.add_argument("--timesteps", type=limits.timesteps, metavar="N",
                     help="env steps per run (default: the hyperparameter file's "
                          f"n_timesteps, else {DEFAULT_TIMESTEPS}; with --resume, the "
                          "run's own total)")
    run.add_argument("--seeds", type=limits.seed, nargs="+", metavar="K",
                     help="seeds, trained one after the other (default: 0)")
    run.add_argument("--out", metavar="DIR",
                     help=f"root of the run folders (default: {DEFAULT_OUT}); its parent "
                          "folder must exist")
    run.add_argument("--resume", action="store_true",
                     help="continue each seed's run from its newest checkpoint")
    run.add_argument("--overwrite", action="store_true",
                     help="delete an existing run folder and start again")
    run.add_argument("--backend", choices=(*BACKEND_CHOICES, BATCH_BACKEND),
                     default=DEFAULT_BACKEND, type=str.lower,
                     help="library that trains: auto (default): sbx if installed, else "
                          "sb3; sb3 (Stable-Baselines3, PyTorch); sbx (SBX, JAX); rsl_rl "
                          "(PPO on the batched env, MuJoCo Warp; docs/batch.md)")
    settings = parser.add_argument_group("settings")
    settings.add_argument("--hyperparams", metavar="FILE.yml|NAME",
                          help="RL-Zoo-style hyperparameter file, or the name of one shipped "
                               f"with rehabbot ({', '.join(settings_names())}); default: "
                               "the shipped file named after the algorithm (sac, td3, ppo, "
                               "tqc, crossq: entries for the -v2 ids, printed); "
                               "sb3-defaults/<algo> for the library's defaults")
    settings.add_argument("--env-kwargs", metavar="JSON",
                          help="keyword arguments for the env, as a JSON object")
    settings.add_argument("--demos", type=limits.demos, metavar="N",
                          help="run the scripted expert for N episodes of the training env "
                               "(seeds: run seed + 20000 + i) and add every transition to the "
                               "replay buffer before learning (sac, td3, tqc, crossq; default "
                               f"{SHIPPED_DEMOS} with the shipped settings, else 0); with "
                               f"--bc, the episodes to clone (default {DEFAULT_BC_EPISODES})")
    settings.add_argument("--bc", action="store_true",
                          help="PPO only: warm-start PPO's actor by behaviour cloning the "
                               "expert's episodes (MSE of the mean action, in units of the "
                               "action bound; Adam, a few epochs; loss before/after in the "
                               "manifest); both backends (PyTorch on sb3, JAX on sbx)")
    envs = parser.add_argument_group("parallel and batched envs")
    envs.add_argument("--n-envs", "--num-envs", dest="n_envs", type=limits.n_envs,
                      metavar="K",
                      help="parallel training envs (default: the file's n_envs, else 1); "
                           "with --backend rsl_rl, batched worlds (default 4096)")
    envs.add_argument("--vec", choices=VEC_ENV_KINDS, default="dummy",
                      help="vector env: in-process (dummy, default), one process per env "
                           "(subproc, started with 'spawn': safe after rendering or with "
                           "threads) or in-process with the envs' physics on threads "
                           "(threads: rehabbot.envs.vector; docs/vector-env.md)")
    envs.add_argument("--time-limit-s", type=limits.time_limit_s, metavar="S",
                      help="--backend rsl_rl: end each run, as finished, after the first "
                           "PPO iteration that ends past S seconds of wall clock (building "
                           "the batched env included; docs/batch.md)")
    logs = parser.add_argument_group("checkpoints and evaluation")
    logs.add_argument("--checkpoint-freq", type=limits.step_period, metavar="N",
                      help=f"checkpoint every N env steps, 0: only at the end (default: "
                           f"{DEFAULT_CHECKPOINT_FREQ})")
    logs.add_argument("--eval-freq", type=limits.step_period, metavar="N",
                      help=f"evaluate every N env steps on a separate env, 0: never "
                           f"(default: {DEFAULT_EVAL_FREQ})")
    logs.add_argument("--eval-episodes", type=limits.episodes, metavar="N",
                      help=f"deterministic episodes per evaluation (default: "
                           f"{DEFAULT_EVAL_EPISODES})")
    logs.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=cmd_train)


def _resume_command(args: argparse.Namespace, env_id: str, algo: str, seeds: Sequence[int],
                    total: int) -> str:
    return shlex.join(["rehabbot", "train", env_short_name(env_id), "--algo", algo,
                       "--timesteps", str(total), "--seeds", *map(str, seeds),
                       "--out", str(args.out), "--resume"])


@cli_command
def cmd_train(args: argparse.Namespace) -> int:
    """Run ``rehabbot train``: each seed in turn; 0 when every run finished, 130/143 when a
    signal stopped a run, or stopped the command before a seed it was asked to train."""
    from rehabbot.cli.needs import require, train_modules
    from rehabbot.common.files import check_parent_exists
    from rehabbot.common.signals import handling_signals

    require("rehabbot train" + (f" --backend {args.backend}" if args.backend != "auto"
                                else ""), train_modules(args.algo, args.backend))
    if args.out is None:
        args.out = DEFAULT_OUT  # created with its parents
    else:
        check_parent_exists(args.out)
    if args.backend == BATCH_BACKEND:
        return train_batched_cli(args, DEFAULT_SEEDS, parse_env_kwargs(args.env_kwargs))
    if args.time_limit_s is not None:
        raise CliError(f"--time-limit-s {args.time_limit_s:g} is used by --backend "
                       f"{BATCH_BACKEND} only, not --backend {args.backend}", EXIT_USAGE)
    stop = SeedStop()
    with handling_signals(stop):
        return _train_seeds(args, stop)


def _stop_text(signum: int) -> str:
    return signal.Signals(signum).name


def _train_seeds(args: argparse.Namespace, stop: SeedStop) -> int:
    from rehabbot.rl import runs
    from rehabbot.rl.training import TrainingInterrupted, execute, plan_seeds

    hyperparams, demos = args.hyperparams, args.demos
    shipped = hyperparams is None and not args.resume
    if shipped:
        hyperparams = shipped_settings(args.algo)
        if demos is None and args.algo in OFF_POLICY:
            demos = SHIPPED_DEMOS  # what the shipped settings were validated with
    plans = plan_seeds(args.env, args.algo, args.seeds or DEFAULT_SEEDS, args.timesteps,
                       args.out, hyperparams=hyperparams,
                       env_kwargs=parse_env_kwargs(args.env_kwargs), resume=args.resume,
                       overwrite=args.overwrite, n_envs=args.n_envs,
                       checkpoint_freq=args.checkpoint_freq, eval_freq=args.eval_freq,
                       eval_episodes=args.eval_episodes, progress_bar=not args.no_progress,
                       vec=args.vec, backend=args.backend, demos=demos, bc=args.bc)
    if stop.signum is not None:
        print(f"stopped by {_stop_text(stop.signum)} before training: nothing was written",
              flush=True)
        return 128 + stop.signum
    new_runs = [plan for plan in plans if plan.skip is None and plan.resume is None]
    if shipped and new_runs and hyperparams is not None:
        buffer = ""
        if args.demos is None and args.algo in OFF_POLICY:
            buffer = (f", with {SHIPPED_DEMOS} scripted-expert episodes in the replay buffer "
                      "(--demos 0: none)")
        print(f"settings: the shipped {hyperparams!r} file, entry {new_runs[0].hp.entry!r} "
              f"({settings_path(hyperparams)}){buffer}; {library_defaults(args.algo)} trains "
              "with the library's defaults instead", file=sys.stderr, flush=True)
    for change in new_runs[0].hp.backend_changes if new_runs else ():
        used = "dropped" if change["used"] is None else f"-> {change['used']}"
        print(f"note: {new_runs[0].backend} backend: {change['key']} {change['given']!r} "
              f"{used} ({change['why']})", file=sys.stderr, flush=True)
    for index, plan in enumerate(plans):
        left = [p for p in plans[index:] if p.skip is None]
        if stop.signum is not None and left:
            command = _resume_command(args, plan.env_id, plan.algo, [p.seed for p in left],
                                      plan.total_timesteps)
            print(f"stopped by {_stop_text(stop.signum)} before seed {left[0].seed}: "
                  f"{len(left)} run{'s' if len(left) > 1 else ''} not trained; continue "
                  f"with: {command}", flush=True)
            return 128 + stop.signum
        if plan.skip is not None:
            print(plan.skip, flush=True)
            continue
        if plan.resume:
            action, source = "resuming", "the checkpoint's"
            start = f"from {plan.resume.steps} "
        else:
            action, source, start = "training", plan.hp.source, ""
        envs = f"{plan.n_envs} env{'s' if plan.n_envs > 1 else ''}"
        extra = ""
        if plan.demos and plan.resume is None:
            extra = f", {'cloning' if plan.bc else 'first'} {plan.demos} expert episodes"
        print(f"{plan.run_dir}: {action} {plan.algo} on {plan.env_id} ({plan.backend}), seed "
              f"{plan.seed}, {start}to {plan.total_timesteps} steps ({envs}, hyperparameters: "
              f"{source}{extra})", flush=True)
        try:
            run_dir = execute(plan)
        except TrainingInterrupted as err:
            command = _resume_command(args, plan.env_id, plan.algo, [p.seed for p in plans],
                                      plan.total_timesteps)
            print(f"{err.run_dir}: interrupted at {err.timesteps_done} steps, checkpoint "
                  f"{err.checkpoint}; resume with: {command}", flush=True)
            return err.exit_code
        except KeyboardInterrupt:  # a second signal, while setting up or saving at the end
            newest = runs.checkpoints(plan.run_dir)
            if newest:
                command = _resume_command(args, plan.env_id, plan.algo,
                                          [p.seed for p in plans], plan.total_timesteps)
                print(f"{plan.run_dir}: interrupted; newest checkpoint {newest[0][1]}; resume "
                      f"with: {command}", flush=True)
            else:
                print(f"{plan.run_dir}: interrupted before the first checkpoint", flush=True)
            return 128 + signal.SIGINT
        print(runs.run_summary(run_dir), flush=True)
    if stop.signum is not None:  # after the last run had saved its final model
        print(f"received {_stop_text(stop.signum)} once the last run had saved its final "
              "model: every run is finished", file=sys.stderr, flush=True)
    return EXIT_OK
