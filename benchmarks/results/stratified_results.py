"""Success of trained runs on held-out episodes stratified over every exercise x weight level x
patient profile: the per-cell table and, per env and algorithm, the IQM over seeds with a 95 %
percentile-bootstrap interval (rliable's recommendation, :mod:`benchmarks.common.aggregate`).

Each run folder (``.../<env>/<algo>/seed<k>/`` with a ``model.zip``, or a batched run's
``policy.npz``) is evaluated with
deterministic actions on ``--per-cell`` episodes of every cell: each exercise of the id, each
weight level 0..4 and each of three profiles (the 1.75 m, 75 kg man the runs trained on, and two
held out: a 1.60 m, 60 kg woman and a 1.85 m, 90 kg man). A population id's runs
(``rehab-reach-population-v2``) are evaluated with ``--profiles patients`` instead: every patient
of the held-out ``"test"`` population, picked with the reset option ``patient``, stands where a
profile stands. Episode seeds start at ``--seed``
(default 50 000, far from the training seeds, the expert demonstrations' 20 000 + i and the
evaluation callback's) and count up over the cells, the same for every run. The scripted
expert runs the same episodes as a reference. Every number in the output comes from these
episodes; ``--json`` keeps them all (with each episode's seed, cell, outcome and safety rule).

With ``--page docs/results/NAME`` the script writes the results document ``NAME.json``, its
page ``NAME.md`` and the page's figures (``docs/results/figures/NAME/*.png``, matplotlib:
:mod:`benchmarks.results.learning_figures`): a heat map of success per cell for each env and,
where the runs' data hold them, learning curves. Evaluating a run folder keeps its learning
curve with its episodes (:mod:`benchmarks.results.training_curves`: ``training_log.csv``,
``eval/evaluations.npz`` or the monitor files), so that ``--from-json`` draws it again
without the folder.

Usage::

    python benchmarks/results/stratified_results.py runs/v2 [--per-cell 2] [--seed 50000]
        [--json F] [--sweep SWEEP.yaml ...] [--title TEXT] [--page docs/results/NAME]
    python benchmarks/results/stratified_results.py --from-json docs/results/learning-v2.json \
        --sweep sweeps/results-v2/*.yaml --page docs/results/learning-v2   # render again
    python benchmarks/results/stratified_results.py --from-json docs/results/learning-v2.json \
        --headline [--update-readme README.md]      # the README's headline table

Every published page's exact command is at its top; running it again renders the page and
its figures from the JSON.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.aggregate import iqm_interval
from benchmarks.common.cli import add_page_argument, add_seed_argument, script_command
from benchmarks.common.documents import (
    HEADLINE_END,
    HEADLINE_START,
    make_document,
    make_figure,
    make_table,
    render_markdown,
    replace_block,
    repo_path,
    write_page,
)
from benchmarks.common.figures import figure_file, page_name, write_figures
from benchmarks.common.sweeps import KEY_FIELDS, run_key, sweep_keys
from benchmarks.results import learning_figures
from benchmarks.results.training_curves import SOURCES as CURVE_SOURCES
from benchmarks.results.training_curves import run_curve
from rehabbot.common.extras import missing_module_message
from rehabbot.common.text_tables import markdown_table
from rehabbot.envs.registration import POPULATION_VARIANTS, env_short_name
from rehabbot.rl import runs
from rehabbot.rl.policies import load_policy
from rehabbot.sim.populations import POPULATIONS
from rehabbot.sim.scene import WEIGHT_LEVELS

PROFILES = {
    "m175": None,  # 1.75 m, 75 kg, male: the profile training uses
    "f160": {"height_m": 1.60, "mass_kg": 60.0, "sex": "female"},
    "m185": {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"},
}
# The patients zoo agents are chosen on (benchmarks/results/zoo_select.py): none of them is a test
# patient. A healthy -v2 episode is the same for a deterministic policy whatever its seed (the
# home state has no noise, as in the paper), so validation and test must differ in who is in
# the chair, not only in their seeds.
VALIDATION_PROFILES = {
    "f165": {"height_m": 1.65, "mass_kg": 62.0, "sex": "female"},
    "m170": {"height_m": 1.70, "mass_kg": 68.0, "sex": "male"},
    "m180": {"height_m": 1.80, "mass_kg": 82.0, "sex": "male"},
}
# MyoSuite's legs and arm are one adult size (patient_model="myo" is built for the default profile
# only): their runs are evaluated on the patient they trained on.
TRAINED_PROFILES = {"m175": None}
# A population id's runs are evaluated on the held-out population's patients, each picked with
# the reset option ``patient`` (no profile or condition in common with the "train" population
# the runs drew from). A cell's "profile" is then a patient: a name of the profile and condition
# -> {"patient": its index}.
HELD_OUT_POPULATION = "test"
TRAINING_POPULATION = "train"
SEX_NOUNS = {"female": "woman", "male": "man"}


def population_patients(name: str = HELD_OUT_POPULATION) -> dict[str, dict[str, int]]:
    """The patients of a shipped population as cells: ``f168 spasticity_mas='3'`` (sex, height
    in cm, condition) -> ``{"patient": k}``."""
    population = POPULATIONS[name]
    return {f"{profile.sex[0]}{round(100 * profile.height_m)} {condition.describe()}":
            {"patient": k} for k, (profile, condition) in enumerate(population.patients)}


def population_facts() -> dict[str, Any]:
    """What the patients intro says of the shipped populations, read from them: counts of the
    training population's profiles and conditions, and the held-out one's profiles
    (``a 1.68 m, 62 kg woman``) and condition count."""
    train, test = POPULATIONS[TRAINING_POPULATION], POPULATIONS[HELD_OUT_POPULATION]
    people = [f"a {p.height_m:.2f} m, {p.mass_kg:.0f} kg {SEX_NOUNS[p.sex]}" for p in test.profiles]
    return {"train_profiles": len(train.profiles), "train_conditions": len(train.conditions),
            "test_profiles": len(test.profiles), "test_conditions": len(test.conditions),
            "test_people": " and ".join(people)}


PROFILE_SETS = {"test": PROFILES, "validation": VALIDATION_PROFILES,
                "trained": TRAINED_PROFILES, "patients": population_patients()}
DEFAULT_SEED = 50_000
TITLE = "Results on the -v2 ids: plain networks, held-out episodes"
INTRO = """Every trained run's final model acts deterministically on held-out episodes that cover
every exercise x weight level (0-4) x patient profile (`m175`: the 1.75 m, 75 kg man the runs
trained on; held out: `f160`, a 1.60 m, 60 kg woman, and `m185`, a 1.85 m, 90 kg man):
{per_cell} episodes per cell, {profiles} patients, episode seeds from {seed}. The episode seeds
are far from every seed training used, and the same for every run and for the scripted
expert. On a healthy id the home state has no noise (as in the paper), so a deterministic
policy plays the same episode in a cell whatever its seed: the episodes of a cell are one
episode counted again, and what is held out is the two profiles. "success IQM" is the
interquartile mean of the seeds' success rates with a 95 % percentile-bootstrap interval over
seeds (rliable). Zoo agents are chosen on other patients (`--profiles validation`: a 1.65 m
woman and 1.70 m and 1.80 m men, seeds from 40 000) than these. The per-cell tables pool
every seed of a row; a cell's stops name the safety rule that ended those episodes. Every
episode is in the `data` of this page's JSON file, from which the command below renders this
page again."""
PATIENTS_TITLE = "Results on the population ids: plain networks, held-out patients"
PATIENTS_INTRO = """Every trained run drew a patient of the `"train"` population
({train_profiles} profiles x {train_conditions} conditions) at every episode. Its final model
acts deterministically on held-out episodes that cover every exercise x weight level (0-4) x
patient of the held-out `"test"` population (`--profiles patients`: {test_profiles} other
profiles, {test_people}, x {test_conditions} other conditions; no profile and no condition in
common with training), each picked with the reset option `patient`: {per_cell} episodes per
cell, episode seeds from {seed}, far from every seed training used and the same for every run
and for the scripted expert. A patient is named by sex, height in cm and condition. With a
tremor the episodes of a cell differ with their seeds; otherwise a deterministic policy plays
one episode per cell, counted again. "success IQM" is the interquartile mean of the seeds'
success rates with a 95 % percentile-bootstrap interval over seeds (rliable). The per-cell
tables pool every seed of a row; a cell's stops name the safety rule that ended those episodes.
Every episode is in the `data` of this page's JSON file, from which the command below renders
this page again."""
TRAINED_TITLE = "Results on the musculoskeletal patient: plain networks, the trained patient"
TRAINED_INTRO = """Every trained run's final model acts deterministically on every exercise x
weight level (0-4) of the patient it trained on (`m175`: MyoSuite's models are one adult size, so
no other patient can be seated; `--profiles trained`): {per_cell} episodes per cell, episode
seeds from {seed}, far from every seed training used and the same for every run and for the
scripted expert. The home state has no noise, so a deterministic policy plays the same episode
in a cell whatever its seed: this page measures whether a policy finishes every exercise at
every weight level on this patient, not how it carries over to other patients. "success IQM"
is the interquartile mean of the seeds' success rates with a 95 % percentile-bootstrap
interval over seeds (rliable). Every episode is in the `data` of this page's JSON file, from
which the command below renders this page again."""
SUMMARY_COLUMNS = ("env", "algo", "training (from the runs' manifests)", "seeds",
                   "success per seed", "success IQM [95 % CI]", "expert")
HEADLINE_COLUMNS = ("env", "algo", "success IQM [95 % CI]", "expert")


def find_runs(roots: Sequence[Path]) -> list[Path]:
    """Run folders (a manifest and a final model) below ``roots``."""
    found = []
    for root in roots:
        found += [m.parent for m in sorted(Path(root).rglob(runs.MANIFEST_NAME))
                  if runs.final_model(m.parent) is not None]
    return found


def cell_envs(env_id: str, kwargs: dict) -> tuple[dict[int, gym.Env], dict[int, str]]:
    """The env of each weight level (one env for all where the id accepts every level) and
    the levels the env refuses for this patient, with its reason (a scene that cannot hold a
    heavy profile's limb, e.g. the FR3 with the 1.85 m man at levels 3 and 4). An env that
    refuses every level raises its error: that is bad arguments, not a patient too heavy."""
    try:
        env = gym.make(env_id, **kwargs)
        return dict.fromkeys(WEIGHT_LEVELS, env), {}
    except ValueError as err:
        first_error = err
    envs, refused = {}, {}
    for level in WEIGHT_LEVELS:
        try:
            envs[level] = gym.make(env_id, **kwargs, weight_level=level)
        except ValueError as err:
            refused[level] = str(err)
    if not envs:
        raise first_error
    return envs, refused


def is_population_id(env_id: str) -> bool:
    """Whether ``env_id`` draws a patient from a population each episode."""
    return env_id in POPULATION_VARIANTS


def cell_setup(env_id: str, env_kwargs: dict, profile: dict | None) -> tuple[dict, dict]:
    """The env kwargs and reset options of one patient of a cell: a profile (``profile=``),
    the training profile (None) or a held-out population's patient (``{"patient": k}``: the
    held-out population, and ``patient`` at reset). A population id takes only patients, and
    only it takes them (``ValueError`` naming the id and the profile set to use)."""
    population = is_population_id(env_id)
    if (profile is not None and "patient" in profile) != population:
        raise ValueError(f"{env_short_name(env_id)} is evaluated with --profiles "
                         f"{'patients' if population else 'test, validation or trained'}, "
                         f"not on {profile!r}")
    kwargs = dict(env_kwargs)
    if population:
        kwargs["patients"] = HELD_OUT_POPULATION
        return kwargs, {"patient": profile["patient"]}
    if profile is not None:
        kwargs["profile"] = profile
    return kwargs, {}


def evaluate_cells(spec: str, env_id: str, env_kwargs: dict, per_cell: int,
                   seed: int, refused: list[dict] | None = None,
                   profiles: dict[str, dict | None] = PROFILES) -> list[dict]:
    """Every episode of ``spec`` (a model path or ``expert``) over the cells of ``env_id``.
    A cell the env refuses (see :func:`cell_envs`) has no episodes; it is appended to
    ``refused`` with the env's reason, and its seeds are skipped, so every other cell keeps
    the seeds it has on every robot."""
    episodes = []
    next_seed = seed
    for profile_name, profile in profiles.items():
        kwargs, options = cell_setup(env_id, env_kwargs, profile)
        envs, refusals = cell_envs(env_id, kwargs)
        if refused is not None:
            refused += [{"profile": profile_name, "weight_level": level, "reason": reason}
                        for level, reason in refusals.items()]
        unique = list({id(env): env for env in envs.values()}.values())
        try:
            policies = {id(env): load_policy(spec, env, seed=0) for env in unique}
            exercises = range(len(unique[0].unwrapped.targets)) if unique else range(0)
            for exercise in exercises:
                for level in WEIGHT_LEVELS:
                    if level not in envs:
                        next_seed += per_cell
                        continue
                    env, policy = envs[level], policies[id(envs[level])]
                    for _ in range(per_cell):
                        obs, info = env.reset(seed=next_seed, options={
                            **options, "exercise": exercise, "weight_level": level})
                        done, steps = False, 0
                        while not done:
                            obs, _, terminated, truncated, info = env.step(policy.act(obs))
                            done, steps = terminated or truncated, steps + 1
                        episodes.append({
                            "seed": next_seed, "profile": profile_name, "exercise": exercise,
                            "weight_level": level, "success": bool(info["is_success"]),
                            "safety_violation": info["safety_violation"], "steps": steps,
                            **({"patient": info["patient"]} if "patient" in info else {})})
                        next_seed += 1
        finally:
            for env in unique:
                env.close()
    return episodes


def training_text(manifest: dict) -> str:
    """How a run trained, from its manifest: library, policy, steps, demonstrations."""
    hp = manifest.get("hyperparameters") or {}
    if manifest.get("backend") == "rsl_rl":  # a batched run (rehabbot.rl.batch_training)
        hidden = "-".join(map(str, hp.get("actor_hidden_dims", [])))
        return (f"rsl_rl PPO on MuJoCo Warp, {hidden} {hp.get('activation')} MLPs, "
                f"{manifest.get('n_envs')} worlds x {hp.get('num_steps_per_env')} steps per "
                f"update, {manifest.get('timesteps_done')} steps"
                + (f" (stopped at its {manifest['time_limit_s']:g} s time limit)"
                   if manifest.get("stopped_by") == "time_limit" else ""))
    demos = (manifest.get("demos") or {}).get("episodes", 0)
    n_steps = (hp.get("kwargs") or {}).get("n_steps")
    if not n_steps:
        steps = ""
    elif manifest.get("algo") == "ppo":  # PPO's n_steps is its rollout, not a return's length
        steps = f"{manifest.get('n_envs', 1)} envs x {n_steps} steps per update, "
    else:
        steps = f"{n_steps}-step returns, "
    cloned = (manifest.get("bc") or {}).get("episodes", 0)
    return (f"{manifest.get('backend')} {hp.get('policy')}, {steps}"
            f"{manifest.get('timesteps_done')} steps"
            + (f", {demos} expert episodes in the buffer" if demos else "")
            + (f", actor cloned from {cloned} expert episodes first" if cloned else ""))


def skrl_run(data: dict, path: str) -> tuple[str, dict]:
    """A run of ``examples/skrl_sac.py`` or ``examples/skrl_ppo.py`` (its ``result.json``) in
    this script's format, and its row: the algorithm the result names, "(skrl)"."""
    names = {json.dumps(v, sort_keys=True): k for k, v in PROFILES.items()}
    episodes = [{**e, "profile": names[json.dumps(e["profile"], sort_keys=True)]}
                for e in data["evaluation"]["episodes"]]
    # Results written before skrl_ppo.py existed are skrl_sac.py's, without "algo"/"training".
    training = data.get("training") or (f"skrl {data['skrl_version']} SAC, 256 x 256 MLPs, "
                                        f"1-step returns, {data['timesteps']} steps")
    return f"{data.get('algo', 'sac')} (skrl)", {
        "run_dir": path, "train_seed": data["seed"], "env_kwargs": data["env_kwargs"],
        "timesteps": data["timesteps"], "episodes": episodes, "training": training}


def row_label(algo: str, run: dict) -> str:
    """Runs of one algorithm are one row, apart from those that trained with expert
    episodes in their buffer (``+ demos``), from an actor cloned from them (``+ bc``), or on
    the batched env (``(rsl_rl)``): rows of their own."""
    training = run.get("training", "")
    if training.startswith("rsl_rl") and not algo.endswith(" (rsl_rl)"):
        return f"{algo} (rsl_rl)"
    if "in the buffer" in training and not algo.endswith(" + demos"):
        return f"{algo} + demos"
    if "actor cloned from" in training and not algo.endswith(" + bc"):
        return f"{algo} + bc"
    return algo


def env_label(env_id: str, env_kwargs: dict) -> str:
    """The env of a row: the id, and the robot where it is not the ids' UR5e (the FR3 hip is
    ``rehabbot/rehab-hip-v2 (fr3)``, a row of its own with the expert on the same robot)."""
    robot = (env_kwargs or {}).get("robot")
    return env_id if robot in (None, "ur5e") else f"{env_id} ({robot})"


def cell_key(episode: dict) -> tuple[int, int, str]:
    return episode["exercise"], episode["weight_level"], episode["profile"]


def run_settings(run: dict) -> dict[str, Any]:
    """How a run trained, as fields: its backend (``sbx``, ``sb3``, ``skrl``), the expert
    episodes it saw and whether its actor was cloned from them (``bc``). From the run's
    ``settings`` where evaluation recorded them from its manifest, else from its ``training``
    text (files written before the field existed)."""
    if "settings" in run:
        return dict(run["settings"])
    text = run.get("training") or ""
    buffer = re.search(r"(\d+) expert episodes in the buffer", text)
    cloned = re.search(r"actor cloned from (\d+) expert episodes", text)
    demos = int((buffer or cloned).group(1)) if buffer or cloned else 0
    return {"backend": text.split(" ", 1)[0] if text else "-", "demos": demos,
            "bc": cloned is not None}


def manifest_settings(manifest: dict) -> dict[str, Any]:
    """:func:`run_settings`' fields from a run's manifest."""
    demos = (manifest.get("demos") or {}).get("episodes", 0)
    cloned = (manifest.get("bc") or {}).get("episodes", 0)
    return {"backend": manifest.get("backend"), "demos": demos or cloned, "bc": bool(cloned)}


def base_algo(label: str) -> str:
    """The algorithm of a row label: ``sac + demos`` -> ``sac``, ``ppo (skrl)`` -> ``ppo``."""
    return label.split(" ")[0]


def run_source(label: str, key: tuple, sweeps: dict[str, set]) -> str:
    """What trained a run: the sweep file (of ``sweeps``) with a trial of its key, the skrl
    example for an skrl run, else ``-`` (a run no named file reproduces)."""
    if label.endswith("(skrl)"):
        return f"examples/skrl_{base_algo(label)}.py"
    found = [path for path, keys in sweeps.items() if key in keys]
    return found[0] if found else "-"


def runs_table(results: dict[tuple[str, str], list[dict]],
               sweeps: dict[str, set] | None = None) -> dict[str, Any]:
    """Every evaluated run and how it trained: the rows a sweep file named on the page must
    reproduce exactly (:mod:`benchmarks.common.sweeps`), and the file (or script) that does."""
    rows = []
    for (label, algo), entries in results.items():
        if algo == "expert":
            continue
        env_id = label.split(" (")[0]
        for run in entries:
            settings = run_settings(run)
            key = run_key(env_id, run.get("env_kwargs"), base_algo(algo), run["train_seed"],
                          run["timesteps"], settings["backend"], settings["demos"],
                          settings["bc"])
            rows.append([env_short_name(env_id), key[1], base_algo(algo), key[3], key[4],
                         key[5], key[6], key[7], run_source(algo, key, sweeps or {})])
    rows.sort(key=lambda row: (row[0], row[1], row[2], row[5], row[6], row[7], row[3]))
    return make_table("runs", "Training runs (what each sweep file trains)",
                      [*KEY_FIELDS, "trained by"], rows,
                      note="A row's `trained by` file trains exactly that run: "
                           "`rehabbot sweep FILE` for a sweep file; `-` where none does.")


def summary_tables(results: dict[tuple[str, str], list[dict]],
                   profiles: Sequence[str] = tuple(PROFILES),
                   patient_column: str = "profile") -> list[dict[str, Any]]:
    """One row per env and algorithm (IQM over seeds), then a per-cell table per row (its
    patients under ``patient_column``: ``profile``, or ``patient`` for a population's)."""
    summary, cell_tables = [], []
    for (env_id, algo), entries in sorted(results.items()):
        if algo == "expert":
            continue
        rates = [float(np.mean([e["success"] for e in r["episodes"]])) for r in entries]
        interval = iqm_interval(rates)
        expert = results.get((env_id, "expert"), [{}])[0].get("episodes", [])
        expert_rate = f"{100 * np.mean([e['success'] for e in expert]):.0f} %" if expert else "-"
        seeds = ", ".join(str(r["train_seed"]) for r in entries)
        per_seed = ", ".join(f"{100 * x:.0f}" for x in rates)
        training = "; ".join(sorted({r.get("training", "-") for r in entries}))
        summary.append([env_short_name(env_id), algo, training, seeds, f"{per_seed} %",
                        f"{interval.format(0, 100)} %", expert_rate])
        by_cell: dict[tuple, list[bool]] = defaultdict(list)
        stops: dict[tuple, list[str]] = defaultdict(list)
        for r in entries:
            for e in r["episodes"]:
                by_cell[cell_key(e)].append(e["success"])
                if e["safety_violation"]:
                    stops[cell_key(e)].append(e["safety_violation"])
        rows = []
        for exercise in sorted({k[0] for k in by_cell}):
            for profile in profiles:
                row: list[Any] = [exercise, profile]
                for level in WEIGHT_LEVELS:
                    cell = by_cell[(exercise, level, profile)]
                    text = f"{sum(cell)}/{len(cell)}" if cell else "n/a"
                    if stops[(exercise, level, profile)]:
                        kinds = sorted(set(stops[(exercise, level, profile)]))
                        text += f" ({len(stops[(exercise, level, profile)])} {'/'.join(kinds)})"
                    row.append(text)
                rows.append(row)
        refusals = {(c["profile"], c["weight_level"]): c["reason"]
                    for r in entries for c in r.get("refused_cells", [])}
        note = None
        if refusals:
            cells = ", ".join(f"{p} l{lv}" for p, lv in sorted(refusals))
            reason = next(iter(refusals.values())).split(";")[0]
            note = f"n/a: the env refuses {cells} (no episodes, not counted): {reason}."
        cell_tables.append(make_table(
            f"cells/{env_short_name(env_id)}/{algo}",
            f"{env_short_name(env_id)} / {algo}",
            ["exercise", patient_column, *(f"l{lv}" for lv in WEIGHT_LEVELS)], rows,
            section="Success per cell (all seeds; stops in brackets)", note=note))
    head = make_table("summary", "Success per env and algorithm", SUMMARY_COLUMNS, summary)
    return [head, *cell_tables]


def summarize(results: dict[tuple[str, str], list[dict]],
              profiles: Sequence[str] = tuple(PROFILES)) -> str:
    """:func:`summary_tables` as Markdown, each table under its caption (and its note)."""
    parts = []
    for table in summary_tables(results, profiles):
        parts.append(f"{table['caption']}\n\n"
                     + markdown_table(table["columns"], table["rows"])
                     + (f"\n\n{table['note']}" if table.get("note") else ""))
    return "\n\n".join(parts)


def headline_markdown(document: dict[str, Any]) -> str:
    """The README's short table from a learning document: env, algo, success IQM and the
    expert's success, one row per row of its summary table."""
    summary = next(t for t in document["tables"] if t["id"] == "summary")
    keep = [summary["columns"].index(name) for name in HEADLINE_COLUMNS]
    return markdown_table(HEADLINE_COLUMNS, [[row[i] for i in keep] for row in summary["rows"]])


def load_results(paths: Sequence[Path], per_cell: int, seed: int, profile_set: str
                 ) -> tuple[dict[tuple[str, str], list[dict]], str | None]:
    """The runs of ``--json`` files or of results documents (their ``data``), merged, and the
    provenance a document records. Raises :class:`ValueError` for a file of other episodes."""
    results: dict[tuple[str, str], list[dict]] = defaultdict(list)
    provenance = None
    for path in paths:
        saved = json.loads(path.read_text())
        if "schema" in saved:
            provenance = saved.get("provenance") or provenance
            saved = saved["data"]
        held = (saved["per_cell"], saved["seed"], saved.get("profile_set", "test"))
        if held != (per_cell, seed, profile_set):
            raise ValueError(f"{path} holds --per-cell {held[0]} --seed {held[1]} --profiles "
                             f"{held[2]}, not {per_cell}, {seed} and {profile_set}")
        for entry in saved["results"]:
            if entry["algo"] == "expert":
                if (entry["env_id"], "expert") not in results:
                    results[(entry["env_id"], "expert")] += entry["runs"]
                continue
            for run in entry["runs"]:
                results[(entry["env_id"], row_label(entry["algo"], run))].append(run)
    return results, provenance


CELLS_SECTION = "Success per cell at a glance (all seeds pooled)"
CELLS_NOTE = """Each map is one row of the summary table (its seeds pooled, as in the per-cell
tables below) or the scripted expert on the same episodes. Its rows are exercise x {column},
its columns the weight levels 0-4; a cell's colour is the share of its episodes that finished
and its text finished/played. A red frame marks a cell where a safety rule stopped an episode
(the tables below name the rule); grey, a cell the env refuses for that {column}."""
CURVES_SECTION = "Learning curves"
NO_CURVES_NOTE = """**Learning curves.** No run of this page has a learning curve in its data:
these runs were evaluated from their folders (outside the repository, not published) before
this script kept each run's curve with its episodes. Evaluating run folders again
(`stratified_results.py RUNS ... --page ...`) stores their curves in the JSON
(`training_log.csv`, `eval/evaluations.npz` or the monitor files), and the page then draws
them."""


def learning_page_figures(results: dict[tuple[str, str], list[dict]], patients: Sequence[str],
                          patient_column: str, page: str
                          ) -> list[tuple[dict[str, Any], Any]]:
    """The page's figures (document entries) with what draws each: a heat map per env, and
    the learning curves where the runs' data hold them."""
    figures = []
    for k, payload in enumerate(learning_figures.cell_payloads(results, patients,
                                                               patient_column)):
        env = payload["env"]
        entry = make_figure(
            f"cells/{env}", env, figure_file(page, f"cells-{env}"),
            f"Heat maps of the success of {env} per exercise, {patient_column} and weight "
            f"level, one per algorithm and one for the scripted expert", payload,
            after="summary", section=CELLS_SECTION,
            note=CELLS_NOTE.format(column=patient_column) if k == 0 else None)
        figures.append((entry, payload))
    curves = learning_figures.curve_payload(results)
    if curves is not None:
        sources = sorted({run["source"] for panel in curves["panels"] for row in panel["rows"]
                          for run in row["runs"]})
        note = ("The curves come from each run's folder, kept with its episodes: "
                + "; ".join(f"`{source}`: {CURVE_SOURCES[source]}" for source in sources)
                + ". Runs without a curve in the data are not drawn.")
        figures.append((make_figure(
            "curves", "Success rate during training", figure_file(page, "curves"),
            "Learning curves: success rate against env steps per env and algorithm", curves,
            after="summary", section=CURVES_SECTION, note=note), curves))
    return figures


def curve_notes(results: dict[tuple[str, str], list[dict]]) -> list[str]:
    """The page's note that its runs hold no learning curve, where none does."""
    return [] if learning_figures.curve_payload(results) is not None else [NO_CURVES_NOTE]


def draw_learning_figures(document: dict[str, Any], results: dict[tuple[str, str], list[dict]],
                          args: argparse.Namespace) -> list[Path]:
    """Draw the figures ``document`` names beside its page ``args.page``."""
    profiles = PROFILE_SETS[args.profiles]
    patient_column = "patient" if args.profiles == "patients" else "profile"
    drawings = {}
    for entry, payload in learning_page_figures(results, tuple(profiles), patient_column,
                                                page_name(args.page)):
        build = (learning_figures.build_curves_figure if payload["kind"] == "training-curves"
                 else learning_figures.build_cells_figure)
        drawings[entry["id"]] = (lambda build=build, payload=payload: build(payload))
    return write_figures(document, args.page, drawings)


def learning_document(results: dict[tuple[str, str], list[dict]], args: argparse.Namespace,
                      command: str, provenance: str | None) -> dict[str, Any]:
    """The results document of a learning table: the summary, the per-cell tables, the runs
    and, in ``data``, every episode (what ``--from-json`` reads back)."""
    profiles = PROFILE_SETS[args.profiles]
    sweeps = {repo_path(path): set(sweep_keys(path)) for path in args.sweep}
    data = {"per_cell": args.per_cell, "seed": args.seed, "profile_set": args.profiles,
            "profiles": profiles,
            "results": [{"env_id": k[0], "algo": k[1], "runs": v} for k, v in results.items()]}
    title, intro = {"trained": (TRAINED_TITLE, TRAINED_INTRO),
                    "patients": (PATIENTS_TITLE, PATIENTS_INTRO)}.get(args.profiles,
                                                                      (TITLE, INTRO))
    patient_column = "patient" if args.profiles == "patients" else "profile"
    figures = ([figure for figure, _ in learning_page_figures(
        results, tuple(profiles), patient_column, page_name(args.page))]
        if args.page is not None else [])
    return make_document(
        title=args.title or title,
        intro=intro.format(per_cell=args.per_cell, seed=args.seed, profiles=args.profiles,
                           **population_facts()),
        command=command, generated_by=__file__, sweeps=list(sweeps),
        tables=[*summary_tables(results, tuple(profiles), patient_column),
                runs_table(results, sweeps)],
        figures=figures, notes=curve_notes(results),
        seeds={"first_episode_seed": args.seed, "episodes_per_cell": args.per_cell,
               "training_seeds": "per run, in the runs table"},
        settings={"profiles": args.profiles, "actions": "deterministic",
                  "model": "every run's final model"},
        provenance=provenance, data=data)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="*", type=Path, help="folders holding run folders")
    parser.add_argument("--per-cell", type=int, default=2,
                        help="episodes per exercise x weight level x profile (default 2)")
    add_seed_argument(parser, DEFAULT_SEED,
                      help_text=f"first episode seed (default {DEFAULT_SEED})")
    parser.add_argument("--profiles", choices=tuple(PROFILE_SETS), default="test",
                        help="the patients: test (the training profile and two held out; "
                             "the published tables) or validation (three others, on which "
                             "zoo agents are chosen) or trained (the training profile only: "
                             "MyoSuite's legs, one adult size) or patients (a population id's: "
                             "the 12 patients of the held-out \"test\" population)")
    parser.add_argument("--json", type=Path, help="write every episode to this file")
    parser.add_argument("--skrl", type=Path, nargs="+", default=[], metavar="RESULT.json",
                        help="result.json files of examples/skrl_sac.py or skrl_ppo.py, shown "
                             "as rows of their own named by the result's algorithm (their "
                             "episodes are that script's, seeds from 60000)")
    parser.add_argument("--from-json", type=Path, nargs="+", default=[], metavar="FILE",
                        help="render the tables from files written by --json or --page (no "
                             "evaluation; the runs of every file are merged)")
    add_page_argument(parser, "e.g. docs/results/learning-v2")
    parser.add_argument("--sweep", type=Path, nargs="+", default=[], metavar="FILE",
                        help="the sweep files that trained the runs: the page names them and "
                             "its runs table says which file trains each run")
    parser.add_argument("--title", help="the page's title (default: one for the --profiles "
                                        "set); a page's title says what sets it apart")
    parser.add_argument("--provenance", help="where the runs and episodes came from (text "
                                             "recorded on the page; default: the input's)")
    parser.add_argument("--headline", action="store_true",
                        help="print only the short headline table (env, algo, success IQM, "
                             "expert)")
    parser.add_argument("--update-readme", type=Path, metavar="README",
                        help="rewrite the headline table between the lines "
                             f"{HEADLINE_START} and {HEADLINE_END} of this file")
    args = parser.parse_args(argv)
    if args.per_cell < 1:
        parser.error(f"--per-cell {args.per_cell} must be at least 1")
    if args.skrl and args.profiles != "test":
        parser.error("--skrl results hold the test patients' episodes; use --profiles test")
    if args.page and importlib.util.find_spec("matplotlib") is None:
        parser.error(missing_module_message("--page (it draws the page's figures)",
                                            "matplotlib"))
    profiles = PROFILE_SETS[args.profiles]
    found = find_runs(args.roots)
    if not found and not args.skrl and not args.from_json:
        parser.error(f"no run folder with a {runs.MODEL_NAME} under {args.roots}")
    try:
        results, provenance = load_results(args.from_json, args.per_cell, args.seed,
                                           args.profiles)
    except ValueError as err:
        parser.error(str(err))
    for run_dir in found:
        manifest = runs.read_manifest(run_dir) or {}
        env_id, algo = manifest["env_id"], manifest["algo"]
        env_kwargs = manifest.get("env_kwargs") or {}
        refused: list[dict] = []
        try:
            episodes = evaluate_cells(str(runs.final_model(run_dir)), env_id, env_kwargs,
                                      args.per_cell, args.seed, refused, profiles)
        except ValueError as err:
            parser.error(f"{run_dir}: {err}")
        run = {"run_dir": str(run_dir), "train_seed": manifest.get("seed"),
               "env_kwargs": env_kwargs, "timesteps": manifest.get("timesteps_done"),
               "training": training_text(manifest), "settings": manifest_settings(manifest),
               "episodes": episodes, "refused_cells": refused}
        try:
            curve = run_curve(run_dir)
        except ValueError as err:
            parser.error(f"{run_dir}: {err}")
        if curve is not None:
            run["curve"] = curve
        row_env = env_label(env_id, env_kwargs)
        results[(row_env, row_label(algo, run))].append(run)
        rate = np.mean([e["success"] for e in episodes])
        print(f"{run_dir}: {100 * rate:.0f} % of {len(episodes)} episodes", file=sys.stderr,
              flush=True)
        if (row_env, "expert") not in results:
            results[(row_env, "expert")].append({
                "run_dir": None, "train_seed": None, "env_kwargs": env_kwargs,
                "episodes": evaluate_cells("expert", env_id, env_kwargs, args.per_cell,
                                           args.seed, profiles=profiles)})
    for path in args.skrl:
        data = json.loads(path.read_text())
        env_id = data["env"]
        label, run = skrl_run(data, str(path))
        row_env = env_label(env_id, run["env_kwargs"])
        results[(row_env, label)].append(run)
        if (row_env, "expert") not in results:
            results[(row_env, "expert")].append({
                "run_dir": None, "train_seed": None, "env_kwargs": run["env_kwargs"],
                "episodes": evaluate_cells("expert", env_id, run["env_kwargs"], args.per_cell,
                                           args.seed)})
    command = script_command(__file__, argv)
    document = learning_document(results, args, command, args.provenance or provenance)
    if args.headline:
        print(headline_markdown(document))
    else:
        print(render_markdown(document))
    if args.page:  # the figures first: a page never names a figure that was not drawn
        for path in draw_learning_figures(document, results, args):
            print(f"wrote {repo_path(path)}", file=sys.stderr)
        write_page(document, args.page)
    if args.update_readme:
        text = args.update_readme.read_text(encoding="utf-8")
        try:
            args.update_readme.write_text(replace_block(text, headline_markdown(document)),
                                          encoding="utf-8")
        except ValueError as err:
            parser.error(f"{args.update_readme}: {err}")
    if args.json:
        args.json.write_text(json.dumps({"command": command, **document["data"]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
