"""A safety stop never pays (design decision 6): an episode that a safety rule stops
earns less than holding still from the states it passed through (the start, its middle and
the step just before the stop), by a margin: undiscounted from every one of them, and for
gamma in {0.95, 0.99, 0.999} from every one after which the episode never out-earned the
hold step for step before it stopped (the penalty is built so: ``rehabbot.tasks.reward``, the
gap ``G`` to the best hold). An episode that made headway first (moved towards the target,
which holding does not) can be worth more than holding under discounting whatever the stop
costs: 0.95^195 = 5e-5, so a penalty 195 steps later would need to be 20,000 times the
progress; that is progress paying, not the stop, and such comparisons are counted, not
asserted (``benchmarks/probes/stop_audit.py`` prints the counts).

The property test drives random joints of random ids, in every control mode, in a random
direction at a random fraction of the action bound into a stop and checks it by replaying the
episode and holding still (``benchmarks.common.reward_audit.push_audit``)."""

import gymnasium as gym
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rehabbot  # noqa: F401  (registers the ids)
from benchmarks.common.reward_audit import push_audit
from rehabbot.envs.registration import ENV_SPECS

MODES = ("joint_delta", "joint_position", "joint_velocity", "torque")
GAMMAS = (None, 0.95, 0.99, 0.999)
IDS = tuple(ENV_SPECS)
_ACTION_SIZES: dict[str, int] = {}


def _action_size(env_id: str) -> int:
    if env_id not in _ACTION_SIZES:
        env = gym.make(env_id)
        _ACTION_SIZES[env_id] = env.action_space.shape[0]
        env.close()
    return _ACTION_SIZES[env_id]


@st.composite
def pushes(draw):
    env_id = draw(st.sampled_from(IDS))
    return {"env_id": env_id, "control_mode": draw(st.sampled_from(MODES)),
            "joint": draw(st.integers(0, _action_size(env_id) - 1)),
            "sign": draw(st.sampled_from((1, -1))),
            "fraction": draw(st.floats(0.3, 1.0)),
            "exercise": draw(st.integers(0, 1)),
            "weight_level": draw(st.integers(0, 4)),
            "seed": draw(st.integers(0, 2**16))}


def check_stop_never_pays(push: dict) -> list:
    """Every comparison of the push's stop with holding still that fails the property (none
    when the push ends in no stop, or holding still could not avoid a stop either)."""
    audit = push_audit(**push, gammas=GAMMAS)
    failures = []
    for comparison in audit.comparisons:
        if comparison.hold_stop is not None:
            continue  # both episodes stop: no hold to compare with
        if comparison.gamma is not None and comparison.headway:
            continue  # discounted, the progress made first can pay (module docstring)
        if audit.stop_pays(comparison):  # by less than half the margin, discounted
            failures.append((audit.violation, audit.stop_step, comparison))
    return failures


@pytest.mark.slow
@settings(max_examples=40, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(push=pushes())
def test_a_stop_never_pays(push):
    failures = check_stop_never_pays(push)
    assert not failures, (push, failures)
