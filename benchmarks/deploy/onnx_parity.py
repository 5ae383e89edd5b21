"""ONNX export parity: onnxruntime's actions against the policies they were exported from, on
observations of recorded episodes (``rehabbot.rl.onnx_export``).

* every ``-v2`` agent the zoo ships (``rehabbot.zoo.available()``): exported with
  ``export_onnx("zoo:ENV/AGENT", ...)``, then the agent runs ``--episodes`` episodes in its env
  (reset seeds ``--seed``, ``--seed`` + 1, ...; more until ``--observations`` observations
  are recorded) and the ONNX file's actions are compared with the agent's
  (``ZooPolicy.predict``) on every observation of them, as one batch;
* a Stable-Baselines3 SAC and a PPO (with VecNormalize statistics, which the ONNX graph
  applies itself), trained ``--train-steps`` steps on rehab-knee-v2 with seed 0, saved as a
  run folder and exported from it as ``rehabbot export RUN_DIR`` does: the ONNX file's actions
  against ``model.predict(obs, deterministic=True)`` (on the normalised observation) and
  against the zoo program the export went through, on the observations of the model's own
  episodes.

Each row also gives the file's size and onnxruntime's time for one action (one observation,
one thread, median over the recorded observations). The floor: every gap at most 1e-5.

Usage::

    python benchmarks/deploy/onnx_parity.py [--episodes 5] [--observations 1000]
        [--train-steps 300] [--page docs/results/onnx-parity] [--doc docs/deployment/export.md]

``--doc`` writes the worst gaps into the page's marked block (``<!-- onnx-parity: start -->``
... ``<!-- onnx-parity: end -->``). Needs ``pip install "rehabbot[onnx,train]"``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run as a script: make `benchmarks` importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.cli import add_page_argument, add_seed_argument, announce, script_command
from benchmarks.common.documents import (
    make_document,
    make_table,
    replace_block,
    table_markdown,
    write_page,
)
from benchmarks.common.machine import describe_machine
from rehabbot.envs.registration import env_short_name
from rehabbot.rl import zoo
from rehabbot.rl.onnx_export import (
    PARITY_TOLERANCE,
    export_onnx,
    load_onnx_policy,
    record_episodes,
    resolve_policy,
)

SB3_ENV = "rehabbot/rehab-knee-v2"
SB3_SEED = 0
DOC_START = "<!-- onnx-parity: start -->"
DOC_END = "<!-- onnx-parity: end -->"
INTRO = """onnxruntime's actions against the policies the ONNX files were exported from
(`rehabbot export POLICY --format onnx`), on every observation of recorded episodes: each
shipped `-v2` zoo agent against its NumPy actor (`ZooPolicy.predict`), and a
Stable-Baselines3 SAC and PPO, briefly trained and exported from their run folder, against
their own `predict(obs, deterministic=True)`. The floor is 1e-5 on every action entry."""


@dataclass
class Row:
    """One policy's comparison."""

    policy: str
    robot: str
    network: str
    head: str
    episodes: int
    observations: int
    max_gap: float  # the largest |ONNX - reference| over every observation and action entry
    max_gap_program: float  # against the zoo program the export went through
    file_kb: float
    microseconds_per_action: float


def network(ops: Sequence[str], metadata: dict[str, Any], path: Path) -> str:
    """``50-256-256-6 relu``: the layer widths (from the graph) and the hidden activation."""
    import onnx
    from onnx import numpy_helper

    model = onnx.load(path)
    constants = {t.name: t for t in model.graph.initializer}
    widths = [len(metadata["observation_names"])]
    for node in model.graph.node:
        if node.op_type == "Gemm":
            widths.append(int(numpy_helper.to_array(constants[node.input[1]]).shape[0]))
    hidden = next((op for op in ops if op not in ("normalize", "tracking_error", "dense",
                                                  "batch_norm", "clip", "unscale")), "")
    return "-".join(map(str, widths)) + (f" {hidden}" if hidden else "")


def head(ops: Sequence[str]) -> str:
    """The deterministic head: what follows the last dense layer."""
    last = max(k for k, op in enumerate(ops) if op == "dense")
    return " + ".join(ops[last + 1:]) or "-"


def time_actions(policy: Any, observations: np.ndarray) -> float:
    """onnxruntime's median microseconds for one action (batch of one)."""
    times = []
    for obs in observations:
        start = time.perf_counter()
        policy.predict(obs)
        times.append(time.perf_counter() - start)
    return 1e6 * statistics.median(times)


def gap(actions: np.ndarray, expected: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(actions, np.float64) - expected)))


def zoo_row(env_id: str, agent: str, folder: Path, episodes: int, at_least: int,
            seed: int) -> Row:
    spec = f"zoo:{env_short_name(env_id)}/{agent}"
    path = folder / f"{env_short_name(env_id)}-{agent}.onnx"
    meta = export_onnx(spec, path)
    policy, reference = load_onnx_policy(path), zoo.load_spec(spec)
    recorded = record_episodes(reference, env_id, meta["env_kwargs"], episodes, seed, at_least)
    observations = np.concatenate(recorded)
    actions = policy.predict(observations)[0]
    difference = gap(actions, reference.predict(observations)[0])
    return Row(policy=spec, robot=meta["robot"], network=network(meta["ops"], meta, path),
               head=head(meta["ops"]), episodes=len(recorded),
               observations=len(observations), max_gap=difference,
               max_gap_program=difference, file_kb=path.stat().st_size / 1024,
               microseconds_per_action=time_actions(policy, observations))


class Normalized:
    """An SB3 model acting on raw observations through its run's VecNormalize statistics."""

    def __init__(self, model: Any, normalize: Any | None) -> None:
        self.model, self.normalize = model, normalize

    def predict(self, obs: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, None]:
        inputs = self.normalize.normalize_obs(obs) if self.normalize is not None else obs
        return self.model.predict(inputs, deterministic=deterministic)[0], None


def sb3_row(algo: str, folder: Path, steps: int, episodes: int, at_least: int,
            seed: int) -> Row:
    """Train ``algo`` (SB3, seed 0) ``steps`` steps, save it as a run folder, export it."""
    import gymnasium as gym
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from rehabbot.rl.vecnormalize_io import save_vecnormalize

    run = folder / f"{algo}-run"
    run.mkdir()
    normalize = None
    if algo == "sac":
        model = sb3.SAC("MlpPolicy", gym.make(SB3_ENV), seed=SB3_SEED, learning_starts=100,
                        buffer_size=10_000)
    else:
        normalize = VecNormalize(DummyVecEnv([lambda: gym.make(SB3_ENV)]), norm_reward=False)
        normalize.seed(SB3_SEED)
        model = sb3.PPO("MlpPolicy", normalize, seed=SB3_SEED, n_steps=128, batch_size=64,
                        n_epochs=1)
    model.learn(steps)
    model.save(run / "model")
    if normalize is not None:
        normalize.training = False
        save_vecnormalize(normalize, run / "vecnormalize.json")
    (run / "manifest.json").write_text(json.dumps({
        "env_id": SB3_ENV, "algo": algo, "seed": SB3_SEED, "backend": "sb3",
        "timesteps_done": int(model.num_timesteps)}))
    path = folder / f"{algo}-sb3.onnx"
    meta = export_onnx(run, path)
    policy, reference = load_onnx_policy(path), Normalized(model, normalize)
    recorded = record_episodes(reference, SB3_ENV, {}, episodes, seed, at_least)
    observations = np.concatenate(recorded)
    actions = policy.predict(observations)[0]
    program, _source = resolve_policy(run)  # the zoo program the export went through
    if program.metadata["weights_sha256"] != meta["weights_sha256"]:
        raise RuntimeError(f"{run}: the zoo program is not the one exported")
    return Row(policy=f"{algo.upper()} (SB3, {int(model.num_timesteps)} steps, seed "
                      f"{SB3_SEED}){', VecNormalize' if normalize is not None else ''}",
               robot=meta["robot"], network=network(meta["ops"], meta, path),
               head=head(meta["ops"]),
               episodes=len(recorded),
               observations=len(observations),
               max_gap=gap(actions, reference.predict(observations)[0]),
               max_gap_program=gap(actions, program.predict(observations)[0]),
               file_kb=path.stat().st_size / 1024,
               microseconds_per_action=time_actions(policy, observations))


def parity_table(rows: Sequence[Row], table_id: str, caption: str, reference: str,
                 note: str, program: bool) -> dict[str, Any]:
    """The rows as a table; ``program``: with the gap to the zoo program (where the
    reference is not the program itself)."""
    cells = [[row.policy, row.robot, row.network, row.head, row.episodes, row.observations,
              f"{row.max_gap:.1e}", *([f"{row.max_gap_program:.1e}"] if program else []),
              "yes" if max(row.max_gap, row.max_gap_program) <= PARITY_TOLERANCE else "NO",
              f"{row.file_kb:.0f}", f"{row.microseconds_per_action:.0f}"] for row in rows]
    columns = ["policy", "robot", "network", "head", "episodes", "observations",
               f"max abs gap to {reference}",
               *(["max abs gap to the zoo program"] if program else []), "<= 1e-5",
               "file [KB]", "µs per action"]
    return make_table(table_id, caption, columns, cells,
                      align=["left"] * 4 + ["right"] * (len(columns) - 4), note=note)


def doc_block(rows: Sequence[Row], sb3_rows: Sequence[Row]) -> str:
    """The sentence ``docs/deployment/export.md`` shows between its markers."""
    worst = max(rows, key=lambda row: row.max_gap)
    worst_sb3 = max(sb3_rows, key=lambda row: row.max_gap) if sb3_rows else None
    text = (f"On every observation of their recorded episodes ({min(r.observations for r in rows)}"
            f" to {max(r.observations for r in rows)} per agent), the ONNX files of the "
            f"{len(rows)} shipped `-v2` agents act as the agents within "
            f"{worst.max_gap:.1e} (worst: `{worst.policy}`)")
    if worst_sb3 is not None:
        text += (f", and briefly trained Stable-Baselines3 models as their "
                 f"`predict(obs, deterministic=True)` within {worst_sb3.max_gap:.1e}")
    return text + ("; the floor is 1e-5 ([ONNX export parity](../results/onnx-parity.md), "
                   "`benchmarks/deploy/onnx_parity.py`).")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=5, help="episodes per policy (5)")
    parser.add_argument("--observations", type=int, default=1000,
                        help="more episodes until this many observations (1000)")
    add_seed_argument(parser, help_text="first reset seed (0)")
    parser.add_argument("--train-steps", type=int, default=300,
                        help="SB3 training steps of the SAC and the PPO (300; 0: no SB3 rows)")
    add_page_argument(parser)
    parser.add_argument("--doc", type=Path, metavar="PAGE.md",
                        help="rewrite the block between the onnx-parity markers of PAGE.md")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("episodes", "observations"):
        if getattr(args, name) < 1:
            parser.error(f"--{name}={getattr(args, name)} must be >= 1")
    if args.train_steps < 0 or args.seed < 0:
        parser.error("--train-steps and --seed must be >= 0")
    agents = [(env_id, agent) for env_id, agent in zoo.available() if env_id.endswith("-v2")]
    with tempfile.TemporaryDirectory(prefix="onnx-parity-") as tmp:
        folder = Path(tmp)
        rows = [zoo_row(env_id, agent, folder, args.episodes, args.observations, args.seed)
                for env_id, agent in agents]
        sb3_rows = [sb3_row(algo, folder, args.train_steps, args.episodes, args.observations,
                            args.seed) for algo in ("sac", "ppo")] if args.train_steps else []
    command = script_command(__file__, argv)
    import onnxruntime

    machine = f"{describe_machine()}, onnxruntime {onnxruntime.__version__}"
    announce(command, machine)
    tables = [parity_table(
        rows, "zoo", "The shipped -v2 agents: ONNX against the zoo's NumPy actor",
        "the agent",
        note="Each agent runs its own episodes in the env (and kwargs) it was trained in; a "
             "gap is the largest absolute difference over every action entry of every "
             "observation (the -v2 actions lie in [-1, 1]). `network`: the layer widths and the "
             "hidden activation; `head`: the steps after the last layer. `µs per action`: "
             "onnxruntime, one observation, one thread, median.", program=False)]
    if sb3_rows:
        tables.append(parity_table(
            sb3_rows, "sb3", "Stable-Baselines3 models: ONNX against their deterministic "
                             "predict", "SB3's predict",
            note=f"Trained on {SB3_ENV} with seed {SB3_SEED} and the library's MlpPolicy "
                 "defaults, saved as a run folder and exported from it (through the zoo "
                 "program, as `rehabbot export RUN_DIR`); the PPO run's VecNormalize "
                 "statistics are applied by the graph itself, SB3's predict gets the "
                 "normalised observation. The observations are the model's own episodes.",
            program=True))
    for table in tables:
        print(table_markdown(table), "\n")
    worst = max(row.max_gap for row in [*rows, *sb3_rows])
    print(f"worst gap {worst:.2e} (floor {PARITY_TOLERANCE:g})")
    if args.page is not None:
        write_page(make_document(
            title="ONNX export parity", intro=INTRO, command=command, generated_by=__file__,
            tables=tables, machine=machine,
            seeds={"reset_seed": args.seed, "sb3_seed": SB3_SEED},
            settings={"episodes": args.episodes, "observations": args.observations,
                      "train_steps": args.train_steps, "tolerance": PARITY_TOLERANCE},
            data={"rows": [asdict(row) for row in [*rows, *sb3_rows]]}), args.page)
    if args.doc is not None:
        text = args.doc.read_text(encoding="utf-8")
        args.doc.write_text(replace_block(text, doc_block(rows, sb3_rows), DOC_START,
                                          DOC_END), encoding="utf-8")
    return 0 if worst <= PARITY_TOLERANCE else 1


if __name__ == "__main__":
    sys.exit(main())
