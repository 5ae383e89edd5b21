"""The benchmark scripts run and report what they claim (their figures are measured by hand
and quoted in the README; here only that the tables are produced and consistent)."""

from __future__ import annotations

import re

import pytest

from benchmarks import expert_agreement, step_throughput

ENV = "rehabbot/rehab-reach-v0"


def test_step_throughput_measures_the_env_as_users_make_it(capsys) -> None:
    assert step_throughput.main(["--steps", "30", "--rounds", "3", "--warmup", "5",
                                 "--ids", "rehab-reach-v0"]) == 0
    out = capsys.readouterr().out
    # gym.make's own wrappers: the registration's TimeLimit only.
    assert "wrappers: TimeLimit;" in out
    row = next(line for line in out.splitlines() if line.startswith(f"| {ENV} "))
    cells = [c.strip() for c in row.strip("|").split("|")]
    env_rate, physics_rate = float(cells[1]), float(cells[2])
    share = float(re.match(r"([0-9.]+)%", cells[3]).group(1)) / 100
    assert env_rate > 0 and physics_rate > 0
    assert 0.0 < share <= 1.5  # physics time / env time, noisy at 30 steps


def test_step_throughput_refuses_unknown_ids(capsys) -> None:
    assert step_throughput.main(["--ids", "rehab-elbow-v9"]) == 2
    assert "unknown id(s) rehabbot/rehab-elbow-v9" in capsys.readouterr().err


@pytest.mark.slow
def test_expert_agreement_tells_a_trained_agent_from_one_that_pushes_the_wrong_way() -> None:
    # The shipped PPO agent finishes reach-v1 episodes: it moves the way the expert does.
    rows = expert_agreement.agreement("zoo:rehab-reach-v1/ppo", episodes=1, seed=1000,
                                      max_steps=60)
    assert rows[0]["steps"] == 60 and rows[0]["mean_cosine"] > 0.5
    assert rows[0]["opposing_share"] < 0.1
    # The expert against itself: cosine 1, same size.
    expert = expert_agreement.agreement("expert", episodes=1, seed=1000, max_steps=20,
                                        env_id="rehabbot/rehab-reach-v1")
    assert abs(expert[0]["mean_cosine"] - 1.0) < 1e-6
    assert abs(expert[0]["median_norm_ratio"] - 1.0) < 1e-6
