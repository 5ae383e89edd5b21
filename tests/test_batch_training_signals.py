"""Signals around batched training runs, without compiling a world: a signal that comes while
a run saves its final model lets the run finish and is handed to the command, which stops
before the next seed (130) or, after the last seed, exits 0; a signal while the worlds are
built stops before anything is trained. The runs are stand-ins (monkeypatched), so the tests
need neither MuJoCo Warp nor a GPU; the rule they test is the command's and the trainer's."""

from __future__ import annotations

import argparse
import signal
from pathlib import Path
from typing import Any

import pytest

from rehabbot.cli import train_batch
from rehabbot.common.signals import handling_signals
from rehabbot.rl import batch_training

ENV = "rehabbot/rehab-reach-v2"


def _args(out: Path, seeds: list[int]) -> argparse.Namespace:
    return argparse.Namespace(algo="ppo", vec="dummy", n_envs=8, seeds=seeds, timesteps=192,
                              hyperparams=None, env=ENV, checkpoint_freq=None, resume=False,
                              overwrite=False, time_limit_s=None, out=out, no_progress=True,
                              eval_freq=None, eval_episodes=None, demos=None, bc=False)


def _fake_runs(monkeypatch: pytest.MonkeyPatch, signal_in_seed: int | None) -> list[int]:
    """``train_batched`` stand-in: each seed "finishes" (a run folder), and the seed named
    gets SIGINT while it saves (the trainer hands it on once the run is whole)."""
    trained: list[int] = []

    def fake(plan: Any, report: Any = None) -> Path:
        trained.append(plan.seed)
        plan.run_dir.mkdir(parents=True)
        if plan.seed == signal_in_seed:
            signal.raise_signal(signal.SIGINT)  # to the command's handler, as the trainer does
        return plan.run_dir

    monkeypatch.setattr(batch_training, "train_batched", fake)
    return trained


def test_a_signal_during_a_final_save_stops_before_the_next_seed(tmp_path, monkeypatch,
                                                                 capsys) -> None:
    trained = _fake_runs(monkeypatch, signal_in_seed=0)
    code = train_batch.train_batched_cli(_args(tmp_path, [0, 1, 2]), (0,), None)
    assert code == 128 + signal.SIGINT
    assert trained == [0]
    out = capsys.readouterr().out
    assert "stopped by SIGINT before seed 1: 2 runs not trained" in out
    assert "--seeds 1 2 --out" in out and out.rstrip().endswith("--resume")


def test_a_signal_during_the_last_seeds_final_save_exits_0(tmp_path, monkeypatch,
                                                            capsys) -> None:
    trained = _fake_runs(monkeypatch, signal_in_seed=1)
    assert train_batch.train_batched_cli(_args(tmp_path, [0, 1]), (0,), None) == 0
    assert trained == [0, 1]
    assert "every run is finished" in capsys.readouterr().err


def test_without_a_signal_every_seed_trains(tmp_path, monkeypatch) -> None:
    trained = _fake_runs(monkeypatch, signal_in_seed=None)
    assert train_batch.train_batched_cli(_args(tmp_path, [0, 1, 2]), (0,), None) == 0
    assert trained == [0, 1, 2]


class _Received:
    def __init__(self) -> None:
        self.signals: list[int] = []

    def __call__(self, signum: int, _frame: Any) -> None:
        self.signals.append(signum)


def _plan(tmp_path: Path) -> batch_training.BatchRunPlan:
    return batch_training.BatchRunPlan(ENV, seed=0, total_timesteps=192, out_dir=tmp_path,
                                       num_envs=8)


def test_the_trainer_hands_a_signal_latched_in_its_final_save_to_the_caller(
        tmp_path, monkeypatch) -> None:
    pytest.importorskip("rsl_rl")
    from rehabbot.rl import rsl_vec_env

    monkeypatch.setattr(rsl_vec_env, "RslVecEnv", lambda *args, **kwargs: object())

    def finish_with_a_signal(plan: Any, *_args: Any) -> Path:
        signal.raise_signal(signal.SIGINT)  # latched: the run goes on to its end
        return plan.run_dir

    monkeypatch.setattr(batch_training, "_train_locked", finish_with_a_signal)
    caller = _Received()
    with handling_signals(caller):
        run_dir = batch_training.train_batched(_plan(tmp_path))
    assert run_dir == _plan(tmp_path).run_dir
    assert caller.signals == [signal.SIGINT]


def test_a_signal_while_the_worlds_are_built_trains_nothing(tmp_path, monkeypatch) -> None:
    pytest.importorskip("rsl_rl")
    from rehabbot.rl import rsl_vec_env

    def build_with_a_signal(*_args: Any, **_kwargs: Any) -> object:
        signal.raise_signal(signal.SIGINT)  # latched until the build returns
        return object()

    monkeypatch.setattr(rsl_vec_env, "RslVecEnv", build_with_a_signal)
    monkeypatch.setattr(batch_training, "_train_locked",
                        lambda *_args: pytest.fail("trained after a signal"))
    with pytest.raises(KeyboardInterrupt):
        batch_training.train_batched(_plan(tmp_path))
    assert not _plan(tmp_path).run_dir.exists()
