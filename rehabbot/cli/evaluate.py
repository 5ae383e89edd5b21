"""``rehabbot evaluate MODEL|expert|aan|random|module:attr ...``: every policy on the same
episodes of one env, a table of clinical figures, and per policy ``evaluation.json`` and
``trace.npz`` (:mod:`rehabbot.analysis.evaluation`). Every argument is checked and every model
loaded before the first episode runs, then the output folder is chosen (without ``--out``, one
of its own for each set of policies compared: :func:`.evaluation_folders.default_out_dir`) and
probed. An output folder that holds an earlier evaluation is refused unless ``--overwrite`` is
given (then each file is replaced atomically, and once every new file is written the earlier
evaluation's other files, and the label folders they leave empty, are removed, so the two never
mix; a failed write keeps the earlier file). A label folder that is a symbolic link is refused
(nothing is written or removed through a link), and so is a folder inside a training run that a
live process holds. The command ends with the ``rehabbot plot`` line that draws what it
wrote."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from rehabbot.cli.errors import (
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    bounded_int,
    cli_command,
    env_kwargs_object,
)

DEFAULT_EPISODES = 10
MAX_EPISODES = 100_000  # about a day of 1000-step episodes for one policy
MAX_SEED = 2**31 - 1


def add_evaluate_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``evaluate`` to the ``rehabbot`` subcommands."""
    parser = commands.add_parser(
        "evaluate", help="evaluate trained models, the scripted expert, the assist-as-needed "
             "controller or random actions",
        description="Clinical evaluation of policies on the same episodes of one env. Prints "
                    "a table and writes JSON.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip\n"
               "  rehabbot evaluate expert random --env rehab-reach-v2 --episodes 20\n"
               "  rehabbot evaluate zoo:rehab-reach-v1/ppo expert\n"
               "  rehabbot evaluate zoo:rehab-reach-v1/sac aan expert --env "
               "rehab-reach-spastic-v1\n"
               "  rehabbot evaluate expert --env rehab-reach-population-v1 --env-kwargs "
               "'{\"patients\": \"test\"}'\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip expert random "
               "--episodes 20\n"
               "  rehabbot evaluate runs/rehab-reach-v2/sac/seed0/model.zip --env-kwargs "
               "'{\"weight_level\": 4, \"profile\": {\"height_m\": 1.6, \"mass_kg\": 55, "
               "\"sex\": \"female\"}}'\n"
               "  rehabbot evaluate mypolicies:Hold expert --env rehab-reach-v2  # your own\n\n"
               "module:attr imports the module (from the current folder or PYTHONPATH) and "
               "takes its attribute: an object with predict(obs, deterministic=...) -> "
               "(action, state) is used as it is; a class, or a function without predict, is "
               "called with the env and must return such an object. Its label (output folder) "
               "is its `label` attribute, else its class name.\n\n"
               "The env is --env, or the one the models were trained on (from their run's "
               "manifest.json, or the zoo agent's file). Each policy's files go to "
               "OUT/<label>/evaluation.json and OUT/<label>/trace.npz; with several "
               "policies, OUT/comparison.md; with a population env, OUT/<label>/patients.md "
               "(one row per patient). Without --out, OUT is a folder of its own for the "
               "policies compared, named after their labels: <run>/evaluation for one model "
               "of a training run alone, runs/<env>/evaluation/<labels> for models of "
               "training runs (with other policies or not: `rehabbot plot runs/<env>` draws "
               "it), else runs/evaluation/<env>/<labels>, e.g. "
               "runs/evaluation/rehab-knee-v2/zoo-sac+expert; the command prints it, and the "
               "`rehabbot plot` line that draws it. An OUT holding an earlier evaluation is "
               "refused unless --overwrite is given; a label folder that is a symbolic link, "
               "or a folder of a training run that is being trained, is refused.\n\n"
               "OMP_NUM_THREADS: a model's network runs with one thread (faster for one small "
               "network, and with other processes on the machine) unless OMP_NUM_THREADS is "
               "set.")
    parser.add_argument("policies", nargs="+",
                        metavar="MODEL|zoo:ENV/ALGO|expert|aan|random|module:attr",
                        help="a model .zip saved by `rehabbot train` (or any SB3 PPO/SAC/TD3 "
                             "zip), an agent shipped in the zoo (zoo:rehab-reach-v1/ppo; "
                             "rehabbot zoo list), 'expert' (scripted expert), 'aan' "
                             "(assist-as-needed controller), 'random', or module:attr (your "
                             "own policy; see below)")
    parser.add_argument("--env", metavar="ENV",
                        help="env id, with or without 'rehabbot/' (default: the env the "
                             "models were trained on; required for expert, aan, random and "
                             "module:attr alone)")
    parser.add_argument("--episodes", type=bounded_int(1, MAX_EPISODES),
                        default=DEFAULT_EPISODES, metavar="N",
                        help=f"episodes per policy, 1 to {MAX_EPISODES:,} (default: "
                             f"{DEFAULT_EPISODES})")
    parser.add_argument("--seed", type=bounded_int(0, MAX_SEED), default=0, metavar="S",
                        help=f"episode k is reset with seed S + k (default: 0; 0 <= S <= "
                             f"{MAX_SEED})")
    parser.add_argument("--stochastic", action="store_true",
                        help="sample the model's actions instead of using its mean")
    parser.add_argument("--env-kwargs", type=env_kwargs_object, default=None, metavar="JSON",
                        help="RehabEnv keyword arguments (override the training run's), e.g. "
                             "'{\"weight_level\": 4}'")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="output folder; its parent folder must exist (default: a folder "
                             "of its own for the policies compared, see below)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier evaluation in the output folder (its other "
                             "files, and the label folders they leave empty, are removed once "
                             "the new files are written)")
    parser.set_defaults(func=cmd_evaluate)


def check_no_earlier_evaluation(out_dir: Path, overwrite: bool) -> None:
    """Refuse (:class:`CliError`, exit 2) an output folder that holds an earlier evaluation,
    unless ``overwrite``: with the train command's wording."""
    from rehabbot.analysis.evaluation_folders import earlier_evaluation

    earlier = earlier_evaluation(out_dir)
    if earlier and not overwrite:
        shown = ", ".join(str(path.relative_to(out_dir)) for path in earlier[:3])
        more = f" and {len(earlier) - 3} more" if len(earlier) > 3 else ""
        raise CliError(f"{out_dir} already holds an evaluation ({shown}{more}); choose another "
                       "folder with --out or start over with --overwrite", EXIT_USAGE)


def plot_command(out_dir: Path) -> str:
    """The ``rehabbot plot`` line that draws the evaluation in ``out_dir``."""
    return f"rehabbot plot {shlex.quote(str(out_dir))}"


@cli_command
def cmd_evaluate(args: argparse.Namespace) -> int:
    """Run ``rehabbot evaluate``."""
    from rehabbot.cli.needs import policy_modules, require

    require("rehabbot evaluate", *map(policy_modules, args.policies))
    from rehabbot.analysis import evaluation, evaluation_folders
    from rehabbot.cli.threads import one_torch_thread
    from rehabbot.common.files import check_parent_exists, check_writable_dir

    out = check_parent_exists(args.out, "--out") if args.out is not None else None
    one_torch_thread(args.policies)
    with evaluation.open_evaluator(args.policies, args.env, args.env_kwargs, args.seed,
                                   deterministic=not args.stochastic) as evaluator:
        labels = evaluator.labels
        out_dir = out or evaluation_folders.default_out_dir(args.policies, evaluator.env_id,
                                                            labels)
        evaluation_folders.check_label_folders(out_dir, labels)
        check_no_earlier_evaluation(out_dir, args.overwrite)
        check_writable_dir(out_dir)
        with evaluation_folders.lock_run_folders(out_dir, labels):
            print(f"evaluation folder: {out_dir}", flush=True)
            results = evaluator.run(args.episodes)
            written = write_results(out_dir, results)
            if args.overwrite:  # only now, all written: what the new evaluation did not
                evaluation_folders.remove_earlier_evaluation(out_dir, keep=written)  # replace
    reports = [report for report, _trace in results]
    table = evaluation.format_table(reports)
    print(f"\n{reports[0]['env_id']}, {args.episodes} episodes per policy\n\n{table}")
    patients = evaluation.format_patient_tables(reports)
    if patients:
        print(f"\n{patients}")
    print(f"\nits figures: {plot_command(out_dir)}")
    return EXIT_OK


def write_results(out_dir: Path, results: list[tuple[dict, dict]]) -> list[Path]:
    """Each policy's files in ``out_dir/<label>/`` and, for several, ``comparison.md``
    (each file replaced atomically: a failure keeps the old one); returns what was written."""
    from rehabbot.analysis import evaluation

    written: list[Path] = []
    for report, trace in results:
        folder = evaluation.label_dir(out_dir, report["policy"]["label"])
        json_path, trace_path = evaluation.save_report(report, trace, folder)
        print(f"{report['policy']['label']}: wrote {json_path} and {trace_path}")
        written += [json_path, trace_path]
        patients_path = evaluation.write_patient_table(folder, report)
        if patients_path is not None:
            print(f"{report['policy']['label']}: wrote {patients_path}")
            written.append(patients_path)
    if len(results) > 1:
        written.append(evaluation.write_comparison(out_dir, [r for r, _t in results]))
    return written
