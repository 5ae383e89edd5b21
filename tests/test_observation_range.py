"""What the ``-v2`` observation holds, as the docs say (docs/envs.md, "Which observation values
pass 1"): the space is Box(-2, 2) for every -v2 id; the tanh, one-hot, weight-level and
progress fields stay in [-1, 1]; theta_in_bounds and cuff_force pass 1 in an ordinary episode;
and no page tells a user the observation is in [-1, 1]."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.sim.myo_patient import myo_available

ROOT = Path(__file__).resolve().parents[1]
V2_IDS = sorted(env_id for env_id in gym.registry
                if env_id.startswith("rehabbot/") and env_id.endswith("-v2"))
WITHIN_ONE = ("joint_error_fine", "joint_error", "tool_error_fine", "tool_error", "next_target",
              "setpoint_lead", "joint_velocity", "exercise", "weight_level", "target_progress")
PAST_ONE = ("theta_in_bounds", "phi_in_range", "cuff_force")


@pytest.mark.slow
@pytest.mark.parametrize("env_id", V2_IDS)
def test_every_v2_space_is_box_minus_two_two(env_id):
    if "-myo-" in env_id and not myo_available():
        pytest.skip('the -myo- ids need pip install "rehabbot[myo]"')
    env = gym.make(env_id)
    try:
        space = env.observation_space
        assert space.dtype == np.float32
        assert (space.low == -2.0).all() and (space.high == 2.0).all()
        layout = env.unwrapped.agent_layout
        assert set(layout.names) == set(WITHIN_ONE) | set(PAST_ONE)  # the docs name every one
    finally:
        env.close()


def test_an_arm_pushed_to_its_bound_passes_one_where_the_docs_say():
    """Full positive actions on the reach: the arm's joint sags past its setpoint bound, then
    the cuff-force rule stops the episode with the force above its limit."""
    env = gym.make("rehabbot/rehab-reach-v2")
    layout = env.unwrapped.agent_layout
    obs, _ = env.reset(seed=0, options={"exercise": 0, "weight_level": 4})
    seen = [obs]
    for _ in range(1000):
        obs, _, terminated, truncated, info = env.step(np.ones(6, np.float32))
        seen.append(obs)
        if terminated or truncated:
            break
    env.close()
    assert info["safety_violation"] == "cuff_force"
    seen = np.array(seen)
    assert env.observation_space.contains(seen[-1]) and np.abs(seen).max() <= 2.0
    for name in WITHIN_ONE:
        assert np.abs(seen[:, layout.slice(name)]).max() <= 1.0, name
    assert seen[:, layout.slice("theta_in_bounds")].max() > 1.0
    assert seen[-1, layout.slice("cuff_force")].max() > 1.0


@pytest.mark.parametrize("page", ["README.md", "docs/getting-started.md", "docs/envs.md"])
def test_no_page_says_the_observation_is_within_one(page):
    text = " ".join((ROOT / page).read_text(encoding="utf-8").split())
    wrong = re.findall(r"observation[^.;:]{0,30}? in \[-1, 1\]", text)
    assert wrong == [], wrong
