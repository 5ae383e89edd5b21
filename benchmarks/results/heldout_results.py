"""Held-out patients across the adult envelope: trained agents against the scripted expert.

Every controller (zoo agents, run folders' final models, always the scripted expert) acts
deterministically in each scene (a one-patient id and its robot) on the cohorts of
:mod:`rehabbot.sim.envelope`: **bodies**, every ``"test"`` body (healthy), and **conditions**,
every ``"test-conditions"`` body x condition, each x exercise x weight level 0-4, one episode
per cell (``--tremor-episodes`` for a tremor). ``--split validation`` plays the
``"validation"`` bodies x conditions instead: agents are selected on it (``per_controller``
in the JSON: finished/of per run). Seeds count up from ``--seed`` over the cells, the same for
every controller; a patient or level the scene refuses (``ValueError`` when built) skips its
seeds and is listed with the reason. The headline figure, finished / expert-finished, counts
only the episodes the expert finishes; those it does not are listed per cell with why.

Usage::

    python benchmarks/results/heldout_results.py [--zoo ENV/AGENT ...] [--runs DIR ...]
        [--env ID[@ROBOT] ...] [--split test|validation] [--seed N] [--tremor-episodes 3]
        [--workers N] [--max-bodies N] [--exercises K ...] [--levels L ...] [--json F]
        [--page docs/results/NAME] [--zoo-figures F] [--sweep FILE ...] [--title T]
    python benchmarks/results/heldout_results.py --from-json docs/results/NAME.json \\
        --page docs/results/NAME                                 # render again, no episodes
    python benchmarks/results/heldout_results.py --from-json A.json B.json --page ...  # merged

``--zoo rehab-knee-v2/sac`` names a zoo agent, ``--runs DIR`` the run folders below DIR (each
with its final model), ``--env rehab-hip-v2@fr3`` a scene the expert plays alone. ``--seed``:
60000 (40000 for validation). ``--max-bodies``, ``--exercises`` and ``--levels`` keep a
subset, with the seeds it has in the whole plan (a quick check); ``--workers N`` plays in N
processes; ``--zoo-figures F`` writes the zoo rows' figures for ``rehabbot zoo list``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from itertools import groupby
from multiprocessing import get_context
from pathlib import Path
from typing import Any

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.aggregate import iqm_interval
from benchmarks.common.cli import add_page_argument, add_seed_argument, script_command
from benchmarks.common.documents import (
    document_json,
    make_document,
    make_table,
    render_markdown,
    repo_path,
    write_page,
)
from benchmarks.common.sweeps import sweep_keys
from benchmarks.results import stratified_results as stratified
from rehabbot.envs import registration as reg
from rehabbot.rl import runs, zoo
from rehabbot.rl.policies import POLICY_KEYWORDS, load_policy
from rehabbot.sim.conditions import PatientCondition
from rehabbot.sim.envelope import (
    envelope_bodies,
    envelope_conditions,
    envelope_of,
    nearest_training_body,
)
from rehabbot.sim.patient import PatientProfile
from rehabbot.sim.scene import WEIGHT_LEVELS

SEEDS = {"test": 60_000, "validation": 40_000}
TREMOR_EPISODES = 3
# The parts of a split: part -> the envelope cohort of its bodies and conditions.
PARTS = {"test": {"bodies": "test", "conditions": "test-conditions"},
         "validation": {"validation": "validation"}}
# The breakdown tables of a part: finished / expert-finished per body, per condition.
BREAKDOWNS = {"bodies": ("body",), "conditions": ("condition",),
              "validation": ("body", "condition")}
CELL = ("part", "body", "condition", "exercise", "weight_level")
TITLES = {"test": "Held-out patients across the adult envelope: agents against the expert",
          "validation": "Validation patients across the adult envelope: agents against the "
                        "expert"}
INTRO = """**Held out** means: the test bodies are drawn across each scene's adult envelope
by a seeded Latin hypercube, disjoint from the training and validation bodies and never the
training patient (the 1.75 m, 75 kg man), with each one's distance to the nearest training
body reported below; every exercise x weight level (0-4) is played, and the scripted expert
plays the same episodes.

Every controller acts deterministically. Episode seeds start at {seed} and count up over the
cells, the same for every controller; a patient with a tremor plays {tremor} episodes per
cell, any other one (whose episode does not depend on its seed) one. The headline figure is
**finished / expert-finished**: of the episodes the scripted expert finishes, how many the
controller finishes; the episodes the expert does not finish are listed apart with why, and
"success" counts every episode. A row of run folders gives each training seed's figure and
their IQM with a 95 % percentile-bootstrap interval over seeds (rliable). Every episode is in
the `data` of this page's JSON file, from which the command below renders this page again."""
VALIDATION_INTRO = """The validation bodies (a seeded Latin hypercube over each scene's adult
envelope, disjoint from the training and test bodies) play every exercise x weight level (0-4)
x validation condition, seeds from {seed} ({tremor} episodes per cell for a tremor), the
expert the same episodes: agents are selected on these, never on the test patients."""


@dataclasses.dataclass(frozen=True)
class Target:
    """A scene to evaluate in: a one-patient id and its env kwargs (the robot)."""

    env_id: str
    kwargs: tuple[tuple[str, Any], ...] = ()

    @property
    def env_kwargs(self) -> dict[str, Any]:
        return dict(self.kwargs)

    @property
    def limb(self) -> str:
        return reg.ENV_SPECS[self.env_id][0]["limb"]

    @property
    def robot(self) -> str:
        return self.env_kwargs.get("robot", "ur5e")

    @property
    def label(self) -> str:
        """``rehab-knee-v2``, ``rehab-hip-v2 (fr3)``."""
        return reg.env_short_name(stratified.env_label(self.env_id, self.env_kwargs))


def make_target(env_id: str, env_kwargs: dict | None = None) -> Target:
    """The scene a controller of ``env_id`` is evaluated in: a population or condition
    variant's base id (the cohorts bring the patients), with the kwargs other than the
    population's. ``ValueError`` naming an id that seats no patient of an envelope."""
    full = reg.resolve_env_id(env_id)
    full = reg.POPULATION_VARIANTS.get(full, reg.CONDITION_VARIANTS.get(full, (full,))[0])
    kwargs = {k: v for k, v in (env_kwargs or {}).items() if k not in ("patients", "conditions")}
    if reg.entry_point_of(full) != reg.ENTRY_POINT or reg.ENV_SPECS[full][0].get("patient_model"):
        raise ValueError(f"{env_id!r} seats no patient of the adult envelope (held-out "
                         "evaluation takes the one-limb ids of the rigid patient)")
    envelope_of(reg.ENV_SPECS[full][0]["limb"], kwargs.get("robot", "ur5e"))
    return Target(full, tuple(sorted(kwargs.items())))


def parse_target(text: str) -> Target:
    """``rehab-knee-v2`` or ``rehab-hip-v2@fr3`` (the robot after ``@``)."""
    env_id, _, robot = text.partition("@")
    return make_target(env_id, {"robot": robot} if robot else {})


def body_name(body: PatientProfile | dict) -> str:
    """``f153 75 kg``: sex, height in cm and mass."""
    b = body if isinstance(body, dict) else dataclasses.asdict(body)
    return f"{b['sex'][0]}{round(100 * b['height_m'])} {b['mass_kg']:g} kg"


@dataclasses.dataclass(frozen=True)
class Patient:
    """One patient of a part: a body and a condition."""

    part: str
    body: PatientProfile
    condition: PatientCondition

    def record(self) -> dict[str, str]:
        return {"part": self.part, "body": body_name(self.body),
                "condition": self.condition.describe()}


@dataclasses.dataclass(frozen=True)
class Planned:
    """One planned episode: a patient, an exercise, a weight level and the episode's seed."""

    patient: Patient
    exercise: int
    weight_level: int
    seed: int

    def record(self) -> dict[str, Any]:
        return {"seed": self.seed, **self.patient.record(), "exercise": self.exercise,
                "weight_level": self.weight_level}


def cohort(split: str, target: Target) -> list[Patient]:
    """The patients of a split for a scene: parts in order, bodies outermost."""
    return [Patient(part, body, condition) for part, name in PARTS[split].items()
            for body in envelope_bodies(name, target.limb, target.robot)
            for condition in envelope_conditions(name)]


def plan_episodes(patients: Sequence[Patient], exercises: int, seed: int,
                  tremor_episodes: int = TREMOR_EPISODES) -> list[Planned]:
    """Every episode, seeds counting up from ``seed`` over patient, exercise, weight level
    (and a tremor patient's episodes): the same for every controller."""
    plan, next_seed = [], seed
    for patient in patients:
        for exercise in range(exercises):
            for level in WEIGHT_LEVELS:
                for _ in range(tremor_episodes if patient.condition.has_tremor else 1):
                    plan.append(Planned(patient, exercise, level, next_seed))
                    next_seed += 1
    return plan


def subset(plan: Sequence[Planned], max_bodies: int | None = None,
           exercises: Sequence[int] | None = None,
           levels: Sequence[int] | None = None) -> list[Planned]:
    """The episodes of the first ``max_bodies`` bodies of each part, of ``exercises`` and of
    ``levels`` (all where None), keeping the seeds they have in ``plan``."""
    bodies: dict[str, list[PatientProfile]] = defaultdict(list)
    for p in plan:
        if p.patient.body not in bodies[p.patient.part]:
            bodies[p.patient.part].append(p.patient.body)
    return [p for p in plan
            if (max_bodies is None or p.patient.body in bodies[p.patient.part][:max_bodies])
            and (exercises is None or p.exercise in exercises)
            and (levels is None or p.weight_level in levels)]


def exercise_count(target: Target) -> int:
    """The exercises of a scene, built with the envelope's first training body
    (``ValueError`` for kwargs the scene refuses)."""
    body = dataclasses.asdict(envelope_bodies("train", target.limb, target.robot)[0])
    envs, _ = stratified.cell_envs(target.env_id, {**target.env_kwargs, "profile": body})
    try:
        return len(next(iter(envs.values())).unwrapped.targets)
    finally:
        for env in {id(e): e for e in envs.values()}.values():
            env.close()


# --------------------------------------------------------------------------- evaluation


def play(env: Any, policy: Any, planned: Planned) -> dict[str, Any]:
    """One episode: whether it finished, the safety rule that stopped it (or None), steps."""
    obs, info = env.reset(seed=planned.seed, options={"exercise": planned.exercise,
                                                      "weight_level": planned.weight_level})
    done, steps = False, 0
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs))
        done, steps = terminated or truncated, steps + 1
    return {"success": bool(info["is_success"]), "safety_violation": info["safety_violation"],
            "steps": steps}


def evaluate(spec: str, target: Target, plan: Sequence[Planned]
             ) -> tuple[list[dict], list[dict]]:
    """Every episode of ``plan`` the scene takes, played by ``spec`` (``expert``, a zoo spec
    or a model path); and the patients' levels it refuses, with the reason."""
    episodes: list[dict] = []
    refused: list[dict] = []
    model = None  # a trained policy serves every patient; the expert is built per env
    for patient, group in groupby(plan, key=lambda p: p.patient):
        cells = list(group)
        levels = sorted({p.weight_level for p in cells})
        kwargs = {**target.env_kwargs, "profile": dataclasses.asdict(patient.body),
                  "condition": patient.condition.to_dict()}
        try:
            envs, refusals = stratified.cell_envs(target.env_id, kwargs)
        except ValueError as err:  # the scene takes this patient at no level
            envs, refusals = {}, dict.fromkeys(levels, str(err))
        refused += [{**patient.record(), "weight_level": level, "reason": refusals[level]}
                    for level in levels if level in refusals]
        unique = list({id(env): env for env in envs.values()}.values())
        try:
            policies = {}
            for env in unique:
                if model is None or spec in POLICY_KEYWORDS:
                    model = load_policy(spec, env, seed=0)
                policies[id(env)] = model
            if spec in POLICY_KEYWORDS:
                model = None
            episodes += [{**p.record(), **play(envs[p.weight_level],
                                               policies[id(envs[p.weight_level])], p)}
                         for p in cells if p.weight_level in envs]
        finally:
            for env in unique:
                env.close()
    return episodes, refused


def _evaluate_job(job: tuple[str, Target, list[Planned]]) -> tuple[list[dict], list[dict]]:
    return evaluate(*job)


@contextmanager
def one_thread_children() -> Iterator[None]:
    """Processes started inside this block run one thread each (BLAS, OpenMP, XLA)."""
    saved = dict(os.environ)
    os.environ.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
                      XLA_FLAGS=f"{saved.get('XLA_FLAGS', '')} --xla_cpu_multi_thread_eigen="
                                "false intra_op_parallelism_threads=1")
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved)


def run_jobs(jobs: Sequence[tuple[str, Target, list[Planned]]], workers: int = 1
             ) -> list[tuple[list[dict], list[dict]]]:
    """:func:`evaluate` of every job, in order; with ``workers`` > 1 in that many spawned
    processes of one thread each."""
    def report(job: tuple, result: tuple[list[dict], list[dict]]) -> tuple:
        print(f"{job[1].label} / {job[0]}: {sum(e['success'] for e in result[0])} of "
              f"{len(result[0])} episodes finished", file=sys.stderr, flush=True)
        return result

    if workers <= 1:
        return [report(job, evaluate(*job)) for job in jobs]
    with one_thread_children(), ProcessPoolExecutor(
            workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(_evaluate_job, job) for job in jobs]
        return [report(job, future.result()) for job, future in zip(jobs, futures, strict=True)]


# --------------------------------------------------------------------------- controllers


def trained_text(env_id: str, env_kwargs: dict | None) -> str:
    """The env a controller trained on: ``rehab-knee-population-v2 patients=envelope-train``."""
    kwargs = env_kwargs or {}
    return reg.env_short_name(stratified.env_label(env_id, kwargs)) + (
        f" patients={kwargs['patients']}" if "patients" in kwargs else "")


def zoo_controller(name: str) -> tuple[Target, dict[str, Any]]:
    """A zoo agent (``rehab-knee-v2/sac``, ``zoo:`` optional): its scene and its entry
    (``ValueError`` for a name that is not a zoo agent)."""
    env_id, algo = zoo.parse_spec(name if zoo.is_zoo_spec(name) else zoo.ZOO_PREFIX + name)
    policy = zoo.load(env_id, algo)
    kwargs = dict(policy.metadata.get("env_kwargs") or {})
    short = f"{reg.env_short_name(env_id)}/{algo}"
    return make_target(env_id, kwargs), {
        "kind": "zoo", "spec": zoo.ZOO_PREFIX + short, "row": zoo.ZOO_PREFIX + short,
        "trained_on": trained_text(policy.metadata.get("training_env_id", env_id),
                                   {**kwargs, **({"patients": policy.metadata[
                                       "training_patients"]} if "training_patients" in
                                       policy.metadata else {})}),
        "train_seed": policy.metadata.get("seed"),
        "timesteps": policy.metadata.get("training_steps"),
        "weights_sha256": policy.metadata.get("weights_sha256")}


def run_controller(run_dir: Path) -> tuple[Target, dict[str, Any]]:
    """A run folder's final model: its scene (a population id's base id) and its entry."""
    manifest = runs.read_manifest(run_dir) or {}
    kwargs = dict(manifest.get("env_kwargs") or {})
    run = {"kind": "run", "spec": str(runs.final_model(run_dir)), "run_dir": str(run_dir),
           "algo": manifest["algo"], "trained_env_id": manifest["env_id"], "env_kwargs": kwargs,
           "train_seed": manifest.get("seed"), "timesteps": manifest.get("timesteps_done"),
           "training": stratified.training_text(manifest),
           "settings": stratified.manifest_settings(manifest),
           "trained_on": trained_text(manifest["env_id"], kwargs)}
    run["row"] = stratified.row_label(manifest["algo"], run)
    return make_target(manifest["env_id"], kwargs), run


def check_run_roots(roots: Sequence[Path]) -> list[Path]:
    """The run folders below ``roots`` (``stratified_results.find_runs``); ``ValueError``
    naming a root without a run folder, or a run folder without its final model."""
    for root in roots:
        manifests = sorted(Path(root).rglob(runs.MANIFEST_NAME))
        if not manifests:
            raise ValueError(f"--runs {root}: no run folder ({runs.MANIFEST_NAME}) below it")
        for manifest in manifests:
            if runs.final_model(manifest.parent) is None:
                raise ValueError(f"--runs {root}: the run folder {manifest.parent} has no final "
                                 f"model ({runs.MODEL_NAME} or {runs.BATCH_POLICY_NAME}): is "
                                 "it still training?")
    return stratified.find_runs(roots)


# --------------------------------------------------------------------------- the data


def target_data(target: Target, plan: Sequence[Planned],
                results: Sequence[tuple[list[dict], list[dict]]],
                controllers: Sequence[dict]) -> dict[str, Any]:
    """A scene's entry of the data: its parts' bodies and conditions, each body's nearest
    training body, the refused patients, the episodes played (the expert's, which every
    controller must have played) and each controller's outcomes as lists in their order."""
    training = envelope_bodies("train", target.limb, target.robot)
    envelope = envelope_of(target.limb, target.robot)
    patients = list(dict.fromkeys(p.patient for p in plan))
    parts = {part: {"bodies": list(dict.fromkeys(body_name(p.body) for p in patients
                                                 if p.part == part)),
                    "conditions": list(dict.fromkeys(p.condition.describe() for p in patients
                                                     if p.part == part))}
             for part in dict.fromkeys(p.part for p in patients)}
    records = [{k: e[k] for k in ("seed", *CELL)} for e in results[0][0]]
    entries = []
    for controller, (episodes, _) in zip(controllers, results, strict=True):
        if [e["seed"] for e in episodes] != [r["seed"] for r in records]:
            raise ValueError(f"{controller['row']} played other episodes than the expert")
        entries.append({**controller, **{key: [e[key] for e in episodes] for key in
                                         ("success", "safety_violation", "steps")}})
    return {"env_id": target.env_id, "env_kwargs": target.env_kwargs, "label": target.label,
            "limb": target.limb, "robot": target.robot, "parts": parts,
            "distances": [{"body": body_name(b), **nearest_training_body(
                b, training, envelope).to_dict()} for b in dict.fromkeys(
                    p.body for p in patients)],
            "refused": results[0][1], "episodes": records, "controllers": entries}


def episodes_of(target: dict, controller: dict) -> list[dict]:
    """A controller's episodes as records: the scene's episodes with its outcomes."""
    return [{**record, "success": ok, "safety_violation": rule, "steps": steps}
            for record, ok, rule, steps in zip(target["episodes"], controller["success"],
                                               controller["safety_violation"],
                                               controller["steps"], strict=True)]


def expert_of(target: dict) -> list[dict]:
    return episodes_of(target, next(c for c in target["controllers"] if c["kind"] == "expert"))


def expert_relative(episodes: Sequence[dict], expert: Sequence[dict],
                    keep: Callable[[dict], bool] = lambda e: True) -> tuple[int, int]:
    """(finished, of): of the episodes (selected by ``keep``) the expert finishes, how many
    ``episodes`` finishes, matched by seed (``ValueError`` for one it did not play)."""
    wanted = {e["seed"] for e in expert if e["success"] and keep(e)}
    played = {e["seed"]: e["success"] for e in episodes}
    missing = sorted(wanted - played.keys())
    if missing:
        raise ValueError(f"the episodes of seeds {missing[:5]} were not played")
    return sum(bool(played[s]) for s in wanted), len(wanted)


def in_part(part: str) -> Callable[[dict], bool]:
    return lambda e: e["part"] == part


def rows_of(target: dict) -> list[tuple[str, str, list[dict]]]:
    """The scene's controllers other than the expert as rows (trained on, label, entries),
    sorted by label: a zoo agent is a row, run folders are grouped as stratified_results
    groups them."""
    rows: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for c in target["controllers"]:
        if c["kind"] != "expert":
            rows[(c["trained_on"], c["row"])].append(c)
    return sorted(((t, label, cs) for (t, label), cs in rows.items()), key=lambda r: r[1::-1])


def share_iqm(counts: Sequence[tuple[int, int]]) -> str:
    """The IQM [95 % CI] over seeds of finished/of, in %; ``-`` where a seed has no
    expert-finished episode."""
    if not counts or any(of == 0 for _, of in counts):
        return "-"
    return f"{iqm_interval([k / of for k, of in counts]).format(0, 100)} %"


def finished(episodes: Sequence[dict]) -> str:
    """``finished/played``."""
    return f"{sum(bool(e['success']) for e in episodes)}/{len(episodes)}"


def fraction(episodes: Sequence[dict]) -> str:
    """``finished/played (share %)``."""
    share = sum(bool(e["success"]) for e in episodes) / max(len(episodes), 1)
    return f"{finished(episodes)} ({100 * share:.0f} %)" if episodes else "0/0"


def controller_figures(data: dict) -> list[dict[str, Any]]:
    """Per controller other than the expert: finished/of over all its episodes and per part,
    and success over every episode (what a selection step reads)."""
    figures = []
    for target in data["targets"]:
        expert = expert_of(target)
        for c in target["controllers"]:
            if c["kind"] != "expert":
                episodes = episodes_of(target, c)
                done, of = expert_relative(episodes, expert)
                figures.append({
                    **{k: c.get(k) for k in ("kind", "spec", "run_dir", "row", "trained_on",
                                             "train_seed", "weights_sha256")},
                    "target": target["label"], "finished": done, "of": of,
                    "parts": {part: list(expert_relative(episodes, expert, in_part(part)))
                              for part in target["parts"]},
                    "success": [sum(e["success"] for e in episodes), len(episodes)]})
    return figures


def zoo_figures(data: dict, source: str | None) -> dict[str, Any]:
    """The zoo rows' [finished, expert-finished] per part, for ``rehabbot zoo list``."""
    agents = {f["spec"].removeprefix(zoo.ZOO_PREFIX): {**f["parts"],
                                                       "weights_sha256": f["weights_sha256"]}
              for f in controller_figures(data) if f["kind"] == "zoo"}
    return {"source": source, "seed": data["seed"], "agents": agents}


# --------------------------------------------------------------------------- tables


def summary_table(data: dict) -> dict[str, Any]:
    """One row per scene and controller row: each seed's finished / expert-finished and
    their IQM per part, success over every episode (seeds pooled) and the expert's."""
    parts = list(PARTS[data["split"]])
    columns = ["env", "controller", "trained on", "training seeds"]
    for part in parts:
        columns += [f"{part}: finished / expert-finished per seed", f"{part}: IQM [95 % CI]"]
    rows = []
    for target in data["targets"]:
        expert = expert_of(target)
        for trained, label, controllers in rows_of(target):
            played = [episodes_of(target, c) for c in controllers]
            row = [target["label"], label, trained,
                   ", ".join(str(c["train_seed"]) for c in controllers)]
            for part in parts:
                counts = [expert_relative(e, expert, in_part(part)) for e in played]
                row += [", ".join(f"{k}/{n}" for k, n in counts), share_iqm(counts)]
            rows.append([*row, fraction([e for es in played for e in es]), fraction(expert)])
    return make_table("summary", "Finished / expert-finished per scene and controller",
                      [*columns, "success (all episodes)", "expert success"], rows,
                      note="A seed's figure counts, of the episodes the scripted expert "
                           "finishes, those the controller finishes (a zoo agent is one "
                           "seed); success counts every episode, seeds pooled.")


def short_condition(condition: PatientCondition) -> str:
    """A condition in a few words: ``resistive 10 %``, ``active 35 %``, ``MAS 3``,
    ``stiffness x3, ROM x0.7``, ``tremor 6 Hz 1 N·m``, ``healthy``."""
    words = []
    if condition.effort == "resistive":
        words.append(f"resistive {100 * condition.effort_fraction:g} %")
    elif condition.effort == "active_assisted":
        words.append(f"active {100 * condition.strength_fraction:g} %")
    if condition.spasticity_mas != "0":
        words.append(f"MAS {condition.spasticity_mas}")
    if condition.stiffness_scale != 1.0 or condition.rom_scale != 1.0:
        words.append(f"stiffness x{condition.stiffness_scale:g}, ROM x{condition.rom_scale:g}")
    if condition.has_tremor:
        words.append(f"tremor {condition.tremor_hz:g} Hz {condition.tremor_amplitude_nm:g} N·m")
    return ", ".join(words) or condition.describe()


def condition_label(described: str) -> str:
    """The short label of an envelope condition given by its ``describe()`` text (the text
    itself for any other)."""
    labels = {c.describe(): short_condition(c) for split in ("train", "validation", "test",
                                                             "test-conditions")
              for c in envelope_conditions(split)}
    return labels.get(described, described)


def breakdown_table(target: dict, part: str, key: str) -> dict[str, Any]:
    """Finished / expert-finished per ``key`` (``body`` or ``condition``) of a part, one row
    per controller row (seeds pooled), and the expert's finished / played."""
    values = target["parts"][part]["bodies" if key == "body" else "conditions"]
    expert = expert_of(target)
    rows = []
    for _, label, controllers in rows_of(target):
        counts = [[expert_relative(episodes_of(target, c), expert,
                                   lambda e, v=v: e["part"] == part and e[key] == v)
                   for c in controllers] for v in values]
        rows.append([label, *(f"{sum(k for k, _ in cs)}/{sum(n for _, n in cs)}"
                              for cs in counts)])
    rows.append(["expert: finished / played", *(
        finished([e for e in expert if e["part"] == part and e[key] == v])
        for v in values)])
    return make_table(f"{part}/{key}/{target['label']}",
                      f"{target['label']}: {part}, finished / expert-finished per {key}",
                      ["controller", *map(condition_label, values)], rows,
                      section=target["label"])


def stops_table(target: dict) -> dict[str, Any]:
    """Why each controller row did not finish the episodes the expert finishes: the safety
    rule that stopped them, or the time limit, per part (seeds pooled)."""
    expert = expert_of(target)
    wanted = {e["seed"] for e in expert if e["success"]}
    rows, reasons = [], set()
    counted = []
    for _, label, controllers in rows_of(target):
        for part in target["parts"]:
            stops: dict[str, int] = defaultdict(int)
            for c in controllers:
                for e in episodes_of(target, c):
                    if e["part"] == part and e["seed"] in wanted and not e["success"]:
                        stops[e["safety_violation"] or "time limit"] += 1
            reasons |= set(stops)
            counted.append((label, part, stops))
    columns = sorted(reasons - {"time limit"}) + (["time limit"] if "time limit" in reasons
                                                  else [])
    for label, part, stops in counted:
        rows.append([label, part, sum(stops.values()), *(stops.get(r, 0) for r in columns)])
    return make_table(f"stops/{target['label']}",
                      f"{target['label']}: why the episodes the expert finishes were not "
                      "finished", ["controller", "part", "not finished", *columns], rows,
                      section=target["label"],
                      note="Seeds pooled; a safety rule's name is the rule that stopped the "
                           "episode (a stop never pays), the time limit an episode that ran "
                           "out of time.")


def unfinished_table(target: dict) -> dict[str, Any]:
    """The cells where the expert does not finish every episode, with why (the safety rule,
    or the time limit), and each controller row's finished / played there."""
    expert = expert_of(target)
    played = {label: [e for c in cs for e in episodes_of(target, c)]
              for _, label, cs in rows_of(target)}
    failed = dict.fromkeys(tuple(e[k] for k in CELL) for e in expert if not e["success"])
    rows = []
    for cell in failed:
        def here(episodes: Sequence[dict], cell: tuple = cell) -> list[dict]:
            return [e for e in episodes if tuple(e[k] for k in CELL) == cell]
        stops: dict[str, int] = defaultdict(int)
        for e in here(expert):
            if not e["success"]:
                stops[e["safety_violation"] or "time limit"] += 1
        rows.append([*cell[:2], condition_label(cell[2]), *cell[3:], finished(here(expert)),
                     ", ".join(f"{n} {why}" for why, n in sorted(stops.items())),
                     "; ".join(f"{label} {finished(here(es))}"
                               for label, es in played.items()) or "-"])
    return make_table(f"unfinished/{target['label']}",
                      f"{target['label']}: episodes the expert does not finish (left out of "
                      "finished / expert-finished)",
                      ["part", "body", "condition", "exercise", "level", "expert finished",
                       "why", "controllers (finished / played)"], rows,
                      section=target["label"],
                      note=None if rows else "The expert finishes every episode.")


def refused_table(target: dict) -> dict[str, Any]:
    """The patients and levels the scene refuses (no episodes), with the reason."""
    grouped: dict[tuple, list[int]] = defaultdict(list)
    for r in target["refused"]:
        grouped[(r["part"], r["body"], r["condition"], r["reason"])].append(r["weight_level"])
    rows = [[part, body, condition_label(condition), ", ".join(map(str, levels)), reason]
            for (part, body, condition, reason), levels in grouped.items()]
    return make_table(f"refused/{target['label']}",
                      f"{target['label']}: patients the scene refuses (no episodes)",
                      ["part", "body", "condition", "levels", "reason"], rows,
                      section=target["label"],
                      note=None if rows else "The scene takes every patient at every level.")


def distances_table(target: dict) -> dict[str, Any]:
    """Each evaluated body and the nearest training body."""
    rows = [[d["body"], body_name(d["nearest_training_body"]), d["distance"],
             round(100 * d["height_diff_m"], 1), d["mass_diff_kg"], d["same_sex"]]
            for d in target["distances"]]
    return make_table(f"distances/{target['label']}",
                      f"{target['label']}: each body and the nearest training body",
                      ["body", "nearest training body", "distance (envelope units)",
                       "height difference [cm]", "mass difference [kg]", "same sex"], rows,
                      section=target["label"],
                      note="The distance is the norm of the height and mass differences, each "
                           "divided by the envelope's span (rehabbot.sim.envelope).")


def heldout_tables(data: dict, sweeps: dict[str, set] | None = None) -> list[dict[str, Any]]:
    """Every table of the page, computed from the episodes in ``data``."""
    tables = [summary_table(data)]
    trained: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for target in data["targets"]:
        for part in target["parts"]:
            tables += [breakdown_table(target, part, key) for key in BREAKDOWNS[part]]
        tables += [stops_table(target), unfinished_table(target), refused_table(target),
                   distances_table(target)]
        for c in (c for c in target["controllers"] if c["kind"] == "run"):
            trained[(stratified.env_label(c["trained_env_id"], c["env_kwargs"]), c["row"])] += [c]
    return tables + ([stratified.runs_table(trained, sweeps)] if trained else [])


def heldout_document(data: dict, command: str, *, title: str | None = None,
                     sweeps: Sequence[Path] = (), provenance: str | None = None
                     ) -> dict[str, Any]:
    """The results document: its tables and, as its data, every episode."""
    keys = {repo_path(path): set(sweep_keys(path)) for path in sweeps}
    intro = INTRO if data["split"] == "test" else VALIDATION_INTRO
    return make_document(
        title=title or TITLES[data["split"]], command=command, generated_by=__file__,
        intro=intro.format(seed=data["seed"], tremor=data["tremor_episodes"]),
        sweeps=list(keys), tables=heldout_tables(data, keys),
        seeds={"first_episode_seed": data["seed"],
               "tremor_episodes_per_cell": data["tremor_episodes"],
               "training_seeds": "per controller, in the summary"},
        settings={"split": data["split"], "actions": "deterministic",
                  "model": "every run's final model",
                  **({"subset": data["subset"]} if data.get("subset") else {})},
        provenance=provenance, data=pack(data))


# --------------------------------------------------------------------------- CLI


def collect(args: argparse.Namespace, parser: argparse.ArgumentParser
            ) -> tuple[dict[Target, list[dict]], dict[Target, int]]:
    """The scenes, their controllers (the expert first) and exercise counts; a bad value is
    refused naming it."""
    targets: dict[Target, list[dict]] = {}

    def add(target: Target, controller: dict | None = None) -> None:
        targets.setdefault(target, [{"kind": "expert", "spec": "expert", "row": "expert",
                                     "trained_on": "-", "train_seed": None}])
        targets[target] += [controller] if controller else []

    for flag, values, make in (("--env", args.env, lambda v: (parse_target(v),)),
                               ("--zoo", args.zoo, zoo_controller)):
        for value in values:
            try:
                add(*make(value))
            except ValueError as err:  # UsageError, ZooError, PolicyError
                parser.error(f"{flag} {value}: {err}")
    try:
        for run_dir in check_run_roots(args.runs):
            add(*run_controller(run_dir))
    except ValueError as err:
        parser.error(str(err))
    counts = {}
    for target in targets:
        try:
            counts[target] = exercise_count(target)
        except ValueError as err:
            parser.error(f"{target.label}: {err}")
        bad = [k for k in args.exercises or () if not 0 <= k < counts[target]]
        if bad:
            parser.error(f"--exercises {bad[0]}: {target.label} has exercises "
                         f"0-{counts[target] - 1}")
    return targets, counts


def evaluate_all(targets: dict[Target, list[dict]], exercises: dict[Target, int],
                 args: argparse.Namespace) -> dict[str, Any]:
    """Every controller of every scene on the split's plan (``exercises``: each scene's
    exercise count), as the page's data."""
    plans = {target: subset(plan_episodes(cohort(args.split, target), exercises[target],
                                          args.seed, args.tremor_episodes),
                            args.max_bodies, args.exercises, args.levels)
             for target in targets}
    jobs = [(c["spec"], target, plans[target]) for target, cs in targets.items() for c in cs]
    results = iter(run_jobs(jobs, args.workers))
    chosen = {"max_bodies": args.max_bodies, "exercises": args.exercises, "levels": args.levels}
    data = {"split": args.split, "seed": args.seed, "tremor_episodes": args.tremor_episodes,
            "subset": {k: v for k, v in chosen.items() if v is not None} or None,
            "targets": [target_data(target, plans[target], [next(results) for _ in cs], cs)
                        for target, cs in targets.items()]}
    return {**data, "per_controller": controller_figures(data)}


PACKED_TEXT = ("part", "body", "condition")


def pack(data: dict[str, Any]) -> dict[str, Any]:
    """The data as stored: each scene's episodes as columns, the text columns as indices
    into their ``labels`` (thousands of episodes repeat a few patients), and each
    controller's outcomes as 0/1 and as indices into the scene's ``rules`` (0: none)."""
    targets = []
    for target in data["targets"]:
        episodes = target["episodes"]
        labels = {k: list(dict.fromkeys(e[k] for e in episodes)) for k in PACKED_TEXT}
        columns = {k: ([labels[k].index(e[k]) for e in episodes] if k in labels
                       else [e[k] for e in episodes]) for k in ("seed", *CELL)}
        rules = list(dict.fromkeys([None, *(r for c in target["controllers"]
                                            for r in c["safety_violation"])]))
        controllers = [{**c, "success": [int(ok) for ok in c["success"]],
                        "safety_violation": [rules.index(r) for r in c["safety_violation"]]}
                       for c in target["controllers"]]
        targets.append({**target, "episodes": {"columns": columns, "labels": labels},
                        "rules": rules, "controllers": controllers})
    return {**data, "targets": targets}


def unpack(data: dict[str, Any]) -> dict[str, Any]:
    """The data of :func:`pack` with each scene's episodes as records again."""
    targets = []
    for target in data["targets"]:
        stored = target["episodes"]
        if isinstance(stored, dict):
            columns, labels = stored["columns"], stored["labels"]
            names = list(columns)
            stored = [{k: (labels[k][v] if k in labels else v) for k, v in zip(names, row,
                                                                               strict=True)}
                      for row in zip(*(columns[k] for k in names), strict=True)]
        target = {**target, "episodes": stored}
        rules = target.pop("rules", None)
        if rules is not None:  # outcomes stored as 0/1 and as indices into the rules
            target["controllers"] = [
                {**c, "success": [bool(ok) for ok in c["success"]],
                 "safety_violation": [rules[k] for k in c["safety_violation"]]}
                for c in target["controllers"]]
        targets.append(target)
    return {**data, "targets": targets}


def load_data(path: Path) -> tuple[dict[str, Any], str | None]:
    """The data of a results document or of a ``--json`` file, and its provenance (for a
    ``--json`` file, the command that wrote it)."""
    saved = json.loads(Path(path).read_text(encoding="utf-8"))
    if "schema" in saved:
        return unpack(saved["data"]), saved.get("provenance")
    return (unpack({k: v for k, v in saved.items() if k != "command"}),
            f"{repo_path(path)}: {saved.get('command')}")


def merge_data(parts: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One data of several evaluations of the same plan (split, first seed, tremor episodes,
    subset): their scenes in order, a scene in several of them with the controllers of each
    (which must have played the same episodes). ``ValueError`` naming a mismatch."""
    first = parts[0]
    same = ("split", "seed", "tremor_episodes", "subset")
    targets: dict[tuple, dict[str, Any]] = {}
    for part in parts:
        if any(part.get(k) != first.get(k) for k in same):
            raise ValueError("evaluations of different plans cannot be merged: "
                             f"{ {k: part.get(k) for k in same} } against "
                             f"{ {k: first.get(k) for k in same} }")
        for target in part["targets"]:
            key = (target["env_id"], json.dumps(target["env_kwargs"], sort_keys=True))
            if key not in targets:
                targets[key] = {**target, "controllers": list(target["controllers"])}
                continue
            if target["episodes"] != targets[key]["episodes"]:
                raise ValueError(f"{target['label']}: the evaluations played other episodes")
            experts = [next(c for c in t["controllers"] if c["kind"] == "expert")
                       for t in (target, targets[key])]
            outcomes = [[e.get(k) for k in ("success", "safety_violation", "steps")]
                        for e in experts]
            if outcomes[0] != outcomes[1]:
                raise ValueError(f"{target['label']}: the scripted expert played the same "
                                 "episodes differently in two evaluations")
            targets[key]["controllers"] += [c for c in target["controllers"]
                                            if c["kind"] != "expert"]
    data = {**{k: first.get(k) for k in same}, "targets": list(targets.values())}
    return {**data, "per_controller": controller_figures(data)}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="usage:" + __doc__.split("Usage::")[1])
    add = parser.add_argument
    add("--zoo", nargs="+", default=[], metavar="ENV/AGENT", help="zoo agents to evaluate")
    add("--runs", nargs="+", default=[], type=Path, metavar="DIR",
        help="folders of run folders (each with its final model)")
    add("--env", nargs="+", default=[], metavar="ID[@ROBOT]",
        help="scenes the expert plays even without a controller of theirs")
    add("--split", choices=tuple(PARTS), default="test",
        help="test (the bodies and conditions parts) or validation (selection)")
    add_seed_argument(parser, None,
                      help_text="first episode seed (default 60000; 40000 for validation)")
    add("--tremor-episodes", type=int, default=TREMOR_EPISODES,
        help=f"episodes per cell of a patient with a tremor (default {TREMOR_EPISODES})")
    add("--workers", type=int, default=1, help="processes playing controllers (default 1)")
    add("--max-bodies", type=int, metavar="N", help="only the first N bodies of each part")
    add("--exercises", type=int, nargs="+", metavar="K", help="only these exercises")
    add("--levels", type=int, nargs="+", choices=WEIGHT_LEVELS, metavar="L",
        help="only these weight levels")
    add("--json", type=Path, help="write every episode to this file")
    add_page_argument(parser)
    add("--from-json", type=Path, nargs="+", metavar="FILE",
        help="render files of --json or --page again, merged (no evaluation)")
    add("--zoo-figures", type=Path, metavar="FILE",
        help="write the zoo rows' figures for `rehabbot zoo list`")
    add("--sweep", type=Path, nargs="+", default=[], metavar="FILE",
        help="the sweep files that trained the runs (the runs table names them)")
    add("--title", help="the page's title")
    add("--provenance", help="where the runs came from (text recorded on the page)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("tremor_episodes", "workers", "max_bodies"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} {getattr(args, name)} must be at least 1")
    if args.from_json:
        if args.zoo or args.runs or args.env:
            parser.error("--from-json renders a file again: it takes no --zoo, --runs or --env")
        loaded = [load_data(path) for path in args.from_json]
        try:
            data = loaded[0][0] if len(loaded) == 1 else merge_data([d for d, _ in loaded])
        except ValueError as err:
            parser.error(str(err))
        provenance = "; ".join(p for _, p in loaded if p) or None
    else:
        if not (args.zoo or args.runs or args.env):
            parser.error("nothing to evaluate: give --zoo, --runs or --env (or --from-json)")
        args.seed = SEEDS[args.split] if args.seed is None else args.seed
        data, provenance = evaluate_all(*collect(args, parser), args), None
    command = script_command(__file__, argv)
    document = heldout_document(data, command, title=args.title, sweeps=args.sweep,
                                provenance=args.provenance or provenance)
    if args.json:  # the episodes are written first: a closed pipe on stdout loses nothing
        args.json.write_text(document_json({"command": command, **pack(data)}) + "\n")
    if args.page:
        write_page(document, args.page)
    if args.zoo_figures:
        source = args.page.with_suffix(".json") if args.page else args.json
        args.zoo_figures.write_text(json.dumps(zoo_figures(
            data, repo_path(source) if source else None), indent=1) + "\n")
    print(render_markdown(document))
    return 0


if __name__ == "__main__":
    sys.exit(main())
