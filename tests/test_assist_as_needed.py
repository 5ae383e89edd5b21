"""The assist-as-needed controller (rehabbot.rl.assist_as_needed): it finishes the exercises,
its assistance follows Emken et al.'s law, and it is refused where it cannot work."""

import gymnasium as gym
import numpy as np
import pytest

import rehabbot  # noqa: F401  (registers the ids)
from rehabbot.envs.rehab_env import RehabEnv
from rehabbot.rl.assist_as_needed import AssistAsNeeded
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.rl.policies import load_policy


def episode(controller_class, condition=None, limb="arm", exercise=0, **kwargs):
    env = RehabEnv(limb=limb, condition=condition, exercise=exercise, weight_level=0,
                   reward="progress")
    controller = controller_class(env, **kwargs)
    obs, info = env.reset(seed=0)
    steps = 0
    while steps < 1000:
        obs, _, terminated, truncated, info = env.step(controller.predict(obs)[0])
        steps += 1
        if terminated or truncated:
            break
    env.close()
    return info, steps, controller


@pytest.mark.parametrize(("limb", "condition"), [
    ("arm", None), ("arm", {"effort": "active_assisted", "strength_fraction": 0.3}),
    ("knee", {"effort": "resistive", "effort_fraction": 0.05})])
def test_assist_as_needed_finishes_the_exercise(limb, condition):
    info, steps, _ = episode(AssistAsNeeded, condition, limb=limb)
    assert info["is_success"], info["safety_violation"]
    assert steps < 1000


def test_assistance_follows_the_forgetting_law():
    env = RehabEnv(weight_level=0, exercise=0)
    controller = AssistAsNeeded(env, forgetting=0.9, error_gain=0.2)
    obs, _ = env.reset(seed=0)
    action = controller.predict(obs)[0]
    theta = obs[env.layout.slice("theta")].astype(float)
    setpoint = env.controller.setpoint_rad.copy()
    reference = controller._reference.copy()
    # d1 = f d0 + g e0 with d0 = the servo's pre-load (setpoint - theta), e0 = r1 - theta
    expected = 0.9 * (setpoint - theta) + 0.2 * (reference - theta)
    assert np.allclose(controller._assistance, expected)
    assert np.allclose(action, np.clip(theta + expected - setpoint, -env.action_space.high,
                                       env.action_space.high), atol=1e-6)
    # the reference paces towards theta* at most speed_fraction of the bound per decision
    step = np.abs(reference - theta)
    assert step.max() <= 0.75 * env.action_space.high[0] + 1e-9
    env.close()


def test_full_forgetting_and_no_gain_leaves_a_passive_arm_unassisted():
    # f close to 0 and a tiny gain: the robot lets go of the limb's weight, and the arm cannot
    # follow the exercise (what a controller that assists too little does)
    info, _, _ = episode(AssistAsNeeded, None, forgetting=0.01, error_gain=0.001)
    assert not info["is_success"]


def test_assist_as_needed_is_refused_where_it_cannot_work():
    with pytest.raises(ValueError, match="forgetting"):
        AssistAsNeeded(RehabEnv(weight_level=0), forgetting=1.5)
    with pytest.raises(ValueError, match="joint_delta"):
        AssistAsNeeded(RehabEnv(weight_level=0, control_mode="joint_velocity"))
    vec = gym.vector.SyncVectorEnv([lambda: gym.make("rehabbot/rehab-reach-v1")] * 2)
    with pytest.raises(ValueError, match="single RehabEnv"):
        AssistAsNeeded(vec)
    vec.close()
    env = RehabEnv(weight_level=0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        AssistAsNeeded(env).predict(np.zeros((2, 23)))


def test_evaluate_runs_aan_as_a_policy():
    env = gym.make("rehabbot/rehab-reach-v1")
    policy = load_policy("aan", env)
    assert policy.label == "aan"
    obs, _ = env.reset(seed=0)
    action = policy.act(obs)
    assert env.action_space.contains(action)
    env.close()


def test_assist_as_needed_moves_more_smoothly_than_the_expert():
    # it paces a reference instead of jumping at each target: lower peak jerk at the setpoint
    def peak_setpoint_jump(controller_class):
        env = RehabEnv(weight_level=0, exercise=1, reward="progress")
        controller = controller_class(env)
        obs, _ = env.reset(seed=0)
        actions = []
        for _ in range(400):
            action = controller.predict(obs)[0]
            actions.append(action)
            obs, _, terminated, _, _ = env.step(action)
            if terminated:
                break
        env.close()
        return np.abs(np.diff(np.array(actions), axis=0)).max()

    assert peak_setpoint_jump(AssistAsNeeded) < 0.5 * peak_setpoint_jump(ScriptedExpert)


@pytest.mark.parametrize("env_id", ["rehab-reach-v2", "rehab-hip-v2", "rehab-knee-v2"])
def test_assist_as_needed_works_on_the_v2_ids(env_id):
    """The -v2 observation holds no raw angles and its actions are in Box(-1, 1): the
    controller reads the paper's fields from the env and maps its action onto the unit box
    (before, it read the agent observation as angles and the cuff-force rule stopped it)."""
    env = gym.make(f"rehabbot/{env_id}", exercise=0, weight_level=0,
                   condition={"spasticity_mas": "2"})
    controller = AssistAsNeeded(env)
    obs, info = env.reset(seed=0)
    for _ in range(1000):
        action = controller.predict(obs)[0]
        assert env.action_space.contains(action)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    env.close()
    assert info["is_success"], info["safety_violation"]


def test_assist_as_needed_takes_the_same_steps_in_v1_and_v2_units():
    """Mapped back to the controller's box, the -v2 action is the -v1 action."""
    actions = {}
    for version in ("v1", "v2"):
        env = gym.make(f"rehabbot/rehab-reach-{version}", exercise=0, weight_level=0)
        controller = AssistAsNeeded(env)
        obs, _ = env.reset(seed=0)
        steps = []
        for _ in range(20):
            action = controller.predict(obs)[0]
            steps.append(action)
            obs, *_ = env.step(action)
        actions[version] = np.array(steps, dtype=float)
        env.close()
    bound = np.pi / 400
    np.testing.assert_allclose(actions["v2"] * bound, actions["v1"], rtol=1e-5, atol=1e-9)
