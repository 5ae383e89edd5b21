"""The numbers and output paths of ``train``, ``demo``, ``render``, ``sweep``, ``view`` and
``snapshot``: every number option is bounded (found by walking the parser, so a new one is
checked too), a bad value is a usage error naming the option and the value before any work,
and a user's ``--out`` needs an existing parent folder; ``list`` reads the registry; ``train
--help`` shows the essentials and ``--help-all`` the rest."""

from __future__ import annotations

import argparse

import pytest

from rehabbot.cli import build_parser, limits, main

BOUNDED_COMMANDS = ("train", "demo", "render", "sweep", "view", "snapshot")
# The number options that take 0 (a seed, "never", no expert episodes, no weight).
ZERO_ALLOWED = {("train", "--seeds"), ("train", "--checkpoint-freq"), ("train", "--eval-freq"),
                ("train", "--demos"), ("demo", "--demos"), ("demo", "--seed"),
                ("render", "--seed"), ("view", "--weight-level"),
                ("snapshot", "--weight-level")}


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    commands = next(action for action in parser._actions
                    if isinstance(action, argparse._SubParsersAction))
    return dict(commands.choices)


def _number_options() -> list[tuple[str, str, argparse.Action]]:
    found = []
    for command, parser in _subparsers().items():
        if command not in BOUNDED_COMMANDS:
            continue
        for action in parser._actions:
            kind = getattr(action.type, "__name__", None)
            if action.option_strings and kind in ("int", "float"):
                found.append((command, action.option_strings[0], action))
    return found


NUMBER_OPTIONS = _number_options()


def test_the_walk_finds_the_number_options() -> None:
    names = {(command, option) for command, option, _action in NUMBER_OPTIONS}
    assert {("train", "--timesteps"), ("train", "--seeds"), ("train", "--n-envs"),
            ("train", "--time-limit-s"), ("demo", "--episodes"), ("render", "--width"),
            ("render", "--frame-every"), ("sweep", "--cpus"), ("view", "--seconds"),
            ("snapshot", "--profile-mass")} <= names
    assert names >= ZERO_ALLOWED


@pytest.mark.parametrize("command, option, action", NUMBER_OPTIONS,
                         ids=[f"{c} {o}" for c, o, _a in NUMBER_OPTIONS])
def test_no_number_option_is_a_plain_int_or_float(command: str, option: str,
                                                  action: argparse.Action) -> None:
    assert action.type not in (int, float), f"{command} {option} is not bounded"


@pytest.mark.parametrize("value", ["-1", "0", "1e26", "nan", "inf", "-inf"])
@pytest.mark.parametrize("command, option, action", NUMBER_OPTIONS,
                         ids=[f"{c} {o}" for c, o, _a in NUMBER_OPTIONS])
def test_every_number_option_refuses_what_is_out_of_range(command: str, option: str,
                                                          action: argparse.Action,
                                                          value: str) -> None:
    if value == "0" and (command, option) in ZERO_ALLOWED:
        assert action.type(value) == 0
        return
    with pytest.raises(argparse.ArgumentTypeError) as err:
        action.type(value)
    assert repr(value) in str(err.value)


@pytest.mark.parametrize("argv, option, value", [
    (["train", "rehab-reach-v2", "--algo", "sac", "--timesteps", "1e26"], "--timesteps",
     "1e26"),
    (["train", "rehab-reach-v2", "--algo", "sac", "--seeds", "0", "-1"], "--seeds", "-1"),
    (["train", "rehab-reach-v2", "--algo", "sac", "--eval-episodes", "0"], "--eval-episodes",
     "0"),
    (["train", "rehab-reach-v2", "--algo", "ppo", "--backend", "rsl_rl", "--time-limit-s",
      "nan"], "--time-limit-s", "nan"),
    (["demo", "--timesteps", "0"], "--timesteps", "0"),
    (["render", "expert", "--env", "rehab-reach-v2", "--out", "x.gif", "--width", "99999"],
     "--width", "99999"),
    (["render", "expert", "--env", "rehab-reach-v2", "--out", "x.gif", "--frame-every", "0"],
     "--frame-every", "0"),
    (["sweep", "x.yaml", "--cpus", "1e26"], "--cpus", "1e26"),
    (["view", "upper_right", "--seconds", "inf"], "--seconds", "inf"),
    (["snapshot", "upper_right", "--out", "x.png", "--profile-height", "9"],
     "--profile-height", "9"),
    (["snapshot", "upper_right", "--out", "x.png", "--weight-level", "5"], "--weight-level",
     "5"),
])
def test_a_bad_number_is_a_usage_error_naming_option_and_value(tmp_path, monkeypatch, capsys,
                                                               argv, option, value) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and repr(value) in err
    assert list(tmp_path.iterdir()) == []


def test_image_bounds_are_the_scenes_offscreen_buffer() -> None:
    from rehabbot.sim import build_scene

    model = build_scene("upper_right").model
    assert (int(model.vis.global_.offwidth), int(model.vis.global_.offheight)) == \
        (limits.MAX_IMAGE_WIDTH_PX, limits.MAX_IMAGE_HEIGHT_PX)


def test_a_seed_plus_any_step_count_is_a_valid_numpy_seed() -> None:
    import numpy as np

    np.random.seed(limits.MAX_SEED + limits.MAX_TIMESTEPS)  # what SB3 seeds on a resume


# --------------------------------------------------------------------------- --out folders
@pytest.mark.parametrize("argv", [
    ["render", "expert", "--env", "rehab-reach-v2", "--out", "{missing}/expert.gif"],
    ["snapshot", "upper_right", "--out", "{missing}/front.png"],
    ["demo", "--out", "{missing}/demo", "--no-video"],
    ["train", "rehab-reach-v2", "--algo", "sac", "--out", "{missing}/runs"],
    ["sweep", "sweeps/example.yaml", "--out", "{missing}/sweep", "--dry-run"],
], ids=lambda argv: argv[0])
def test_an_out_in_a_missing_folder_is_refused_and_nothing_is_created(tmp_path, monkeypatch,
                                                                      capsys, argv) -> None:
    pytest.importorskip("yaml")
    pytest.importorskip("imageio")
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    missing = tmp_path / "no" / "such"
    argv = [arg.format(missing=missing) if "{missing}" in arg else
            str(repo / arg) if arg.startswith("sweeps/") else arg for arg in argv]
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{str(missing)!r} does not exist" in err
    assert not (tmp_path / "no").exists()


# --------------------------------------------------------------------------- list
def test_list_reads_the_registry_without_building_an_env(monkeypatch, capsys) -> None:
    import gymnasium as gym

    from rehabbot.envs.registration import ENV_SPECS, MYO_VARIANTS

    def refuse(*args, **kwargs):
        raise AssertionError("rehabbot list built an env")

    monkeypatch.setattr(gym, "make", refuse)
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith("rehabbot/")}
    assert list(rows) == list(ENV_SPECS)
    assert all(" [myo] " in rows[env_id] for env_id in MYO_VARIANTS)
    assert all(" - " in row for env_id, row in rows.items() if env_id not in MYO_VARIANTS)


def test_list_into_a_closed_pipe_exits_quietly_as_a_shell_expects() -> None:
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)  # `rehabbot list | head`, once head has what it wanted
    try:
        done = subprocess.run([sys.executable, "-m", "rehabbot", "list"], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert done.returncode == 141 and done.stderr == ""  # 128 + SIGPIPE, no message


@pytest.mark.slow
def test_list_spaces_are_the_built_envs_spaces(capsys) -> None:
    import gymnasium as gym

    from rehabbot.cli.listing import box_text
    from rehabbot.envs.registration import ENV_SPECS

    pytest.importorskip("myo_sim")
    assert main(["list", "--spaces"]) == 0
    captured = capsys.readouterr()
    rows = {line.split()[0]: line for line in captured.out.splitlines()
            if line.startswith("rehabbot/")}
    for env_id in ENV_SPECS:
        env = gym.make(env_id)
        action, observation = env.action_space, env.observation_space
        env.close()
        assert f"  {box_text(action, bounds=True)}  " in rows[env_id]
        assert f"  Box({observation.shape})  " in rows[env_id]
    assert f"id {len(ENV_SPECS)}/{len(ENV_SPECS)} (100 %)" in captured.err


# --------------------------------------------------------------------------- train --help
def _help(capsys, *argv: str) -> str:
    with pytest.raises(SystemExit) as stop:
        main(list(argv))
    assert stop.value.code == 0
    return capsys.readouterr().out


def test_train_help_shows_the_essentials_and_help_all_every_option(capsys,
                                                                   monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    brief = _help(capsys, "train", "--help")
    full = _help(capsys, "train", "--help-all")
    train = _subparsers()["train"]
    options = [action.option_strings[0] for action in train._actions if action.option_strings]
    essentials = ("--algo", "--timesteps", "--seeds", "--out", "--resume", "--overwrite",
                  "--backend", "--help-all")
    for option in options:
        assert option in full, option
        assert (option in brief) == (option in (*essentials, "-h")), option
    assert len(brief.splitlines()) <= 50 < len(full.splitlines())
    assert 'pip install "rehabbot[train]"' in brief
    for group in ("what to train:", "settings:", "parallel and batched envs:",
                  "checkpoints and evaluation:"):
        assert group in full
    assert "Hyperparameter files are RL-Zoo-style YAML" in full
    assert "Hyperparameter files" not in brief


def test_the_parsers_help_texts_are_restored_after_brief_help(capsys) -> None:
    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["train", "--help"])
    capsys.readouterr()
    commands = next(action for action in parser._actions
                    if isinstance(action, argparse._SubParsersAction))
    train = commands.choices["train"]
    assert all(action.help != argparse.SUPPRESS for action in train._actions)
    assert "Hyperparameter files" in train.epilog

