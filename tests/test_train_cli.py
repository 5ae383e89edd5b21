"""``rehabbot train`` when the disk fills and when a signal comes once a run is finished: the
error names the file that could not be written, and the exit code says what happened to the
runs (tiny TD3 runs of Stable-Baselines3, ``--backend sb3``)."""

from __future__ import annotations

import errno
import io
import json
import os
import signal
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason='training tests need "rehabbot[train]"')
pytest.importorskip("yaml", reason="hyperparameter files need PyYAML")

import stable_baselines3.common.monitor as sb3_monitor

import rehabbot.common.files as files
from rehabbot.cli import main
from rehabbot.rl import training

ENV = "rehab-reach-v0"
FULL_ID = "rehabbot/rehab-reach-v0"
TD3 = {"learning_starts": 100, "buffer_size": 1000, "batch_size": 16,
       "policy_kwargs": {"net_arch": [8, 8]}}
STEPS = 200


def _train(tmp_path: Path, *extra: str) -> int:
    import yaml

    hp_file = tmp_path / "td3.yml"
    hp_file.write_text(yaml.safe_dump({FULL_ID: TD3}))
    return main(["train", ENV, "--algo", "td3", "--timesteps", str(STEPS), "--hyperparams",
                 str(hp_file), "--env-kwargs", json.dumps({"max_episode_steps": 50}),
                 "--out", str(tmp_path / "runs"), "--no-progress", "--backend", "sb3",
                 *extra])


def _run_dir(tmp_path: Path, seed: int = 0) -> Path:
    return tmp_path / "runs" / ENV / "td3" / f"seed{seed}"


def _manifest(run_dir: Path) -> dict:
    return json.loads((run_dir / "manifest.json").read_text())


# --------------------------------------------------------------------------- a full disk
def _disk_full() -> OSError:
    return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # names no file, as write() does


class _FullDiskText:
    """A text file whose writes fail as on a full disk once ``allowed`` writes went through."""

    def __init__(self, stream: Any, allowed: int) -> None:
        self._stream = stream
        self._allowed = allowed

    def write(self, data: Any) -> int:
        if self._allowed <= 0:
            raise _disk_full()
        self._allowed -= 1
        return self._stream.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


class _FullDiskBinary(io.BufferedWriter):
    """A binary file (a real ``BufferedWriter``: Stable-Baselines3 checks the type) whose
    writes fail as on a full disk."""

    def write(self, data: Any) -> int:
        raise _disk_full()


def _fill_disk_when_opening(monkeypatch, module: Any, name_part: str, allowed: int = 0) -> None:
    """Make the files whose name holds ``name_part``, opened for writing by ``module``'s
    ``open``, fail to write after ``allowed`` writes (binary files: at once)."""

    def opening(path, mode="r", *args, **kwargs):
        if name_part not in Path(path).name or not set(mode) & set("wa"):
            return open(path, mode, *args, **kwargs)
        if "b" in mode:
            return _FullDiskBinary(io.FileIO(path, mode.replace("b", "")))
        return _FullDiskText(open(path, mode, *args, **kwargs), allowed)

    monkeypatch.setattr(module, "open", opening, raising=False)


@pytest.mark.parametrize("name_part, named", [
    ("manifest.json", "manifest.json"),          # the first file a run writes
    ("rl_model_200_steps.zip", "checkpoints/rl_model_200_steps.zip"),  # the final checkpoint
    ("model.zip", "model.zip"),                  # the final model
])
def test_a_full_disk_names_the_file_train_could_not_write(tmp_path: Path, monkeypatch,
                                                          capsys, name_part: str,
                                                          named: str) -> None:
    _fill_disk_when_opening(monkeypatch, files, name_part)
    assert _train(tmp_path, "--eval-freq", "0") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(_run_dir(tmp_path) / named) in err and "No space left on device" in err


@pytest.mark.parametrize("allowed", [0, 2], ids=["header", "first row"])
def test_a_full_disk_names_the_monitor_file(tmp_path: Path, monkeypatch, capsys,
                                            allowed: int) -> None:
    # allowed=2: the header (two writes) goes through; the first episode's row does not.
    _fill_disk_when_opening(monkeypatch, sb3_monitor, "monitor.csv", allowed=allowed)
    assert _train(tmp_path, "--eval-freq", "0") == 1
    err = capsys.readouterr().err
    assert str(_run_dir(tmp_path) / "monitor" / "train_0.monitor.csv") in err
    assert "No space left on device" in err and err.count("\n") == 1
    if allowed:  # a run that had started says it failed
        assert _manifest(_run_dir(tmp_path))["status"] == "failed"


def test_a_full_disk_names_the_evaluation_log(tmp_path: Path, monkeypatch, capsys) -> None:
    def savez(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez", savez)  # what SB3's EvalCallback writes with
    assert _train(tmp_path, "--eval-freq", "100", "--eval-episodes", "1") == 1
    err = capsys.readouterr().err
    assert str(_run_dir(tmp_path) / "eval" / "evaluations.npz") in err
    assert err.count("\n") == 1


# --------------------------------------------------------------------------- a late signal
def _signal_when(monkeypatch, moment: str) -> None:
    """Send this process SIGINT from inside the final save of the first run: while
    ``model.zip`` is written, or just after the manifest says "finished"."""
    sent = []
    if moment == "saving model.zip":
        real_write = training.atomic_write

        def saving(path, *args, **kwargs):
            if Path(path).name == "model.zip" and not sent:
                sent.append(path)
                signal.raise_signal(signal.SIGINT)
            return real_write(path, *args, **kwargs)

        monkeypatch.setattr(training, "atomic_write", saving)
    else:
        real_run_write = training._Run.write

        def writing(self, **updates):
            real_run_write(self, **updates)
            if updates.get("status") == "finished" and not sent:
                sent.append(self.plan.run_dir)
                signal.raise_signal(signal.SIGINT)

        monkeypatch.setattr(training._Run, "write", writing)


@pytest.mark.parametrize("moment", ["saving model.zip", "after the manifest says finished"])
def test_a_signal_after_the_last_step_of_the_last_run_exits_0(
        tmp_path: Path, monkeypatch, capsys, python_sigint_handler, moment: str) -> None:
    _signal_when(monkeypatch, moment)
    code = _train(tmp_path, "--eval-freq", "0")
    out, err = capsys.readouterr()
    run_dir = _run_dir(tmp_path)
    assert _manifest(run_dir)["status"] == "finished" and (run_dir / "model.zip").is_file()
    assert code == 0, err
    assert f"{run_dir}: {STEPS} steps" in out  # the run's summary
    assert "every run is finished" in err


@pytest.mark.parametrize("moment", ["saving model.zip", "after the manifest says finished"])
def test_a_signal_after_a_run_finished_stops_before_the_next_seed_with_130(
        tmp_path: Path, monkeypatch, capsys, python_sigint_handler, moment: str) -> None:
    _signal_when(monkeypatch, moment)
    code = _train(tmp_path, "--eval-freq", "0", "--seeds", "0", "1", "2")
    out, _err = capsys.readouterr()
    assert code == 130
    assert _manifest(_run_dir(tmp_path, 0))["status"] == "finished"
    assert not _run_dir(tmp_path, 1).exists() and not _run_dir(tmp_path, 2).exists()
    assert "stopped by SIGINT before seed 1: 2 runs not trained" in out
    assert "--seeds 1 2" in out and "--resume" in out
