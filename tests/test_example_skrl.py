"""examples/skrl_sac.py and skrl_ppo.py: tiny runs of skrl's SAC and PPO, their stratified
evaluation and outputs (skrl_common.py), and their rows in
benchmarks/results/stratified_results.py."""

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skrl")
torch = pytest.importorskip("torch")
gym = pytest.importorskip("gymnasium")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
ENV_ID = "rehabbot/rehab-knee-v2"


def load(name: str):
    """An example module by file (``skrl_common`` found beside it, as when run as a script)."""
    sys.path.insert(0, str(EXAMPLES))
    try:
        spec = importlib.util.spec_from_file_location(f"{name}_example", EXAMPLES / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(EXAMPLES))
    return module


@pytest.fixture(scope="module")
def example():
    return load("skrl_sac")


@pytest.fixture(scope="module")
def ppo():
    return load("skrl_ppo")


@pytest.fixture(scope="module")
def common(example):  # the helper module the examples import
    return sys.modules["skrl_common"]


def check_result(common, out: Path, script: str, seed: int, timesteps: int) -> dict:
    """``result.json`` of a run with one episode per cell and 60-step episodes: its command,
    seed, timing and one episode of every profile x exercise x weight level."""
    result = json.loads((out / "result.json").read_text())
    assert result["seed"] == seed and result["timesteps"] == timesteps
    assert result["command"].startswith(f"python examples/{script}")
    assert result["env_kwargs"] == {"max_episode_steps": 60}
    assert result["skrl_version"] == sys.modules["skrl"].__version__
    assert result["wall_clock_seconds"] >= result["train_seconds"] > 0
    episodes = result["evaluation"]["episodes"]
    assert len(episodes) == 1 * 2 * 5 * 3
    assert [e["seed"] for e in episodes] == list(range(60000, 60030))
    for episode in episodes:
        assert set(episode) == {"seed", "profile", "exercise", "weight_level", "success",
                                "safety_violation"}
        assert isinstance(episode["success"], bool)
    cells = {(json.dumps(e["profile"], sort_keys=True), e["exercise"], e["weight_level"])
             for e in episodes}
    assert len(cells) == 30
    assert [e["profile"] for e in episodes[::10]] == [None, *common.PROFILES[1:]]
    rate = np.mean([e["success"] for e in episodes])
    assert result["evaluation"]["success_rate"] == pytest.approx(rate)
    assert not (out / "policy.pt.tmp").exists()
    return result


@pytest.mark.slow
def test_train_evaluate_save(example, common, tmp_path, monkeypatch, capsys):
    trained, real_train = {}, example.train

    def keep(*args, **kwargs):  # the real train, keeping the agent for the checks below
        trained["agent"] = real_train(*args, **kwargs)
        return trained["agent"]

    monkeypatch.setattr(example, "train", keep)
    out = tmp_path / "run"
    argv = ["--env", ENV_ID, "--timesteps", "300", "--learning-starts", "100", "--seed", "3",
            "--episodes-per-cell", "1", "--max-episode-steps", "60", "--out", str(out)]
    assert example.main(argv) == 0
    printed = capsys.readouterr()
    assert printed.out.startswith("success rate: ") and printed.err == ""
    result = check_result(common, out, "skrl_sac.py", seed=3, timesteps=300)
    assert result["algo"] == "sac" and "SAC" in result["training"]

    # SAC updated (the learned entropy coefficient left its initial 0.2), and the saved weights
    # load into a fresh policy that acts as the trained one.
    assert trained["agent"].log_entropy_coefficient.exp().item() != pytest.approx(0.2)
    policy = trained["agent"].policy
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    fresh = example.Policy(env.observation_space, env.action_space, device="cpu")
    fresh.load_state_dict(torch.load(out / "policy.pt", map_location="cpu", weights_only=True))
    fresh.enable_training_mode(False)
    action = common.deterministic_action(fresh, obs)
    np.testing.assert_allclose(action, common.deterministic_action(policy, obs), atol=1e-5)
    assert action.shape == (6,) and np.all(np.abs(action) <= 1.0)
    # Sampled (stochastic) and random exploration actions stay in the box too.
    batch = torch.as_tensor(np.stack([obs] * 64), dtype=torch.float32)
    with torch.no_grad():
        sampled, _ = fresh.act({"observations": batch}, role="policy")
        random, _ = fresh.random_act({"observations": batch}, role="policy")
    assert sampled.abs().max() <= 1.0 and random.abs().max() <= 1.0
    assert not torch.equal(random[0], random[1])  # skrl issue #453: one repeated action
    env.close()


@pytest.mark.slow
def test_ppo_example_end_to_end(ppo, common, tmp_path):
    """The script, run as a user runs it, for two PPO updates (8 envs x 256 steps each): quiet
    (only its own lines), the evaluation, the outputs and the learning curve."""
    out = tmp_path / "run"
    argv = ["--env", ENV_ID, "--timesteps", "4096", "--seed", "3", "--episodes-per-cell", "1",
            "--max-episode-steps", "60", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(EXAMPLES.parent),
                                                        os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(EXAMPLES / "skrl_ppo.py"), *argv], env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stderr == ""  # no warnings or INFO logs from skrl, Gymnasium, torch
    progress, summary = done.stdout.split("success rate: ", 1)
    assert progress.startswith("    4096 steps: ") and progress.count("\n") == 1
    assert summary.rstrip().endswith(f"wrote {out / 'policy.pt'} and {out / 'result.json'}")
    result = check_result(common, out, "skrl_ppo.py", seed=3, timesteps=4096)
    assert result["algo"] == "ppo" and result["settings"] == ppo.SETTINGS
    assert result["training"].startswith("skrl 2.1.1 PPO, 64 x 64 tanh MLPs, 8 envs x 256")
    assert result["steps_per_second"] > 0

    # One row of the learning curve, after the last update: 4096 steps of 60-step episodes
    # (the env's episode statistics), and the learning rate has fallen to 0.
    (row,) = result["learning_curve"]
    assert row["steps"] == 4096 and row["episodes"] >= 8 * (512 // 60) and row["length"] <= 60
    assert 0.0 <= row["success"] <= 1.0 and row["value_loss"] > 0
    assert row["learning_rate"] == 0.0
    # The policy learned (its log std left -1); the saved weights load and act in the box.
    env = gym.make(ENV_ID)
    policy = ppo.Policy(env.observation_space, env.action_space, device="cpu")
    policy.load_state_dict(torch.load(out / "policy.pt", map_location="cpu", weights_only=True))
    log_std = policy.log_std_parameter.detach()
    assert not torch.allclose(log_std, torch.full_like(log_std, -1.0))
    assert row["std"] == pytest.approx(log_std.exp().mean().item(), rel=1e-5)
    action = common.deterministic_action(policy, env.reset(seed=0)[0])
    assert action.shape == (6,) and np.all(np.abs(action) <= 1.0)
    env.close()


@pytest.mark.slow
def test_ppo_env_is_seeded_float32_and_clips(ppo):
    """skrl gets float32 observations, the first reset honours the seed (set_seed), and the
    env resets an ended episode within the step, clipping actions to the box."""
    from skrl.utils import set_seed

    set_seed(7)
    env = ppo.make_env(ENV_ID, {"max_episode_steps": 3})
    obs, _ = env.reset()
    assert obs.dtype == torch.float32 and obs.shape == (8, 50)
    plain = gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID, max_episode_steps=3)] * 8)
    expected, _ = plain.reset(seed=7)
    np.testing.assert_array_equal(obs.numpy(), expected)
    assert not np.array_equal(expected[0], expected[1])  # env i gets seed 7 + i
    for _ in range(3):  # the env counts the values it had to clip: none reach it
        obs, reward, terminated, truncated, info = env.step(torch.full((8, 6), 5.0))
        assert not info["action_clipped"].any()
    assert obs.dtype == torch.float32 and reward.dtype == torch.float32
    assert truncated.all() and not terminated.any()
    assert info["_final_obs"].all() and not info["final_info"]["action_clipped"].any()
    assert not np.array_equal(np.stack(info["final_obs"]), obs.numpy())  # obs: new episodes
    plain.close()
    env.close()


def test_ppo_bootstraps_truncated_episodes_from_their_last_observation(ppo):
    """An episode cut by the time limit is bootstrapped with the value of its last observation
    (``info["final_obs"]``), not of the next episode's first; one that terminates is not, even
    on the time limit's step; both end GAE."""
    from skrl.agents.torch.ppo.ppo import compute_gae
    from skrl.utils import set_seed

    set_seed(0)
    env = ppo.make_env(ENV_ID, {"max_episode_steps": 2})
    agent = ppo.make_agent(env, 4096)
    agent.init()
    # skrl steps the scheduler after each epoch: 4096 steps are 2 updates of 10 epochs.
    assert agent.scheduler.total_iters == 20 and agent.scheduler.end_factor == 0.0
    assert agent.optimizer.param_groups[0]["eps"] == 1e-5
    agent.enable_training_mode(True)
    value = agent.value
    obs, _ = env.reset()
    for step in range(2):
        with torch.no_grad():
            actions, _ = agent.act(obs, None, timestep=step, timesteps=512)
        next_obs, reward, terminated, truncated, info = env.step(actions)
        assert not terminated.any()
        if step == 1:  # the time limit: env 0 also terminates on it
            assert truncated.all()
            terminated[0] = True
        agent.record_transition(observations=obs, states=None, actions=actions,
                                rewards=reward.clone(), next_observations=next_obs,
                                next_states=None, terminated=terminated, truncated=truncated,
                                infos=info, timestep=step, timesteps=512)
        obs = next_obs
    stored = agent.memory.get_tensor_by_name("rewards").view(-1, 8)[1]
    final = torch.as_tensor(np.stack(info["final_obs"]), dtype=torch.float32)
    with torch.no_grad():
        v_final = value.act({"observations": final}, role="value")[0].view(-1)
        v_next = value.act({"observations": next_obs}, role="value")[0].view(-1)
    assert not torch.allclose(v_final, v_next, atol=1e-3)
    expected = reward.view(-1) + 0.99 * v_final
    expected[0] = reward[0, 0]
    torch.testing.assert_close(stored, expected)
    assert len(agent.episodes) == 8 and all(length == 2 for _, length, _ in agent.episodes)
    # GAE as skrl's update computes it (time_limit_bootstrap=True): nothing flows back from the
    # next episode's first value across the episode ends.
    values = agent.memory.get_tensor_by_name("values")[:2]
    rewards = agent.memory.get_tensor_by_name("rewards")[:2]
    returns, _ = compute_gae(
        rewards=rewards, terminated=agent.memory.get_tensor_by_name("terminated")[:2],
        truncated=agent.memory.get_tensor_by_name("truncated")[:2], values=values,
        last_values=torch.full_like(values[0], 1e6), discount_factor=0.99,
        lambda_coefficient=0.95, time_limit_bootstrap=agent.cfg.time_limit_bootstrap)
    torch.testing.assert_close(returns[1], rewards[1])
    env.close()


@pytest.mark.slow
def test_stratified_results_renders_both_examples(tmp_path, monkeypatch, capsys):
    """``--skrl`` takes result.json files of both examples: each is a row named by the
    result's algorithm (an older SAC result without one is SAC's), with its training
    described from the result, its seed and its success."""
    from benchmarks.results import stratified_results

    def result(algo: str | None, seed: int, successes: list[bool], **extra) -> Path:
        cells = [(p, x, lv) for p in (None, {"height_m": 1.60, "mass_kg": 60.0, "sex": "female"},
                                      {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"})
                 for x in range(2) for lv in range(5)]
        episodes = [{"seed": 60000 + i, "profile": p, "exercise": x, "weight_level": lv,
                     "success": ok, "safety_violation": None if ok else "cuff_force"}
                    for i, ((p, x, lv), ok) in enumerate(zip(cells, successes, strict=True))]
        data = {"env": ENV_ID, "env_kwargs": {}, "seed": seed, "timesteps": 1000,
                "skrl_version": "2.1.1", **({"algo": algo} if algo else {}), **extra,
                "evaluation": {"episodes": episodes}}
        path = tmp_path / f"{algo}-{seed}.json"
        path.write_text(json.dumps(data))
        return path

    ppo_runs = [result("ppo", 0, [True] * 30, training="skrl 2.1.1 PPO, 64 x 64 tanh MLPs"),
                result("ppo", 1, [True] * 24 + [False] * 6,
                       training="skrl 2.1.1 PPO, 64 x 64 tanh MLPs")]
    old_sac = result(None, 0, [False] * 30)
    expert_calls = []

    def expert(spec, env_id, env_kwargs, per_cell, seed, *_, **__):
        expert_calls.append((spec, env_id))
        return [{"seed": seed, "profile": "m175", "exercise": 0, "weight_level": 0,
                 "success": True, "safety_violation": None}]

    monkeypatch.setattr(stratified_results, "evaluate_cells", expert)
    assert stratified_results.main(["--skrl", *map(str, ppo_runs), str(old_sac)]) == 0
    text = re.sub(" +", " ", capsys.readouterr().out)  # the Markdown tables' padding out
    assert ("| rehab-knee-v2 | ppo (skrl) | skrl 2.1.1 PPO, 64 x 64 tanh MLPs | 0, 1 | "
            "100, 80 % |") in text
    assert ("| rehab-knee-v2 | sac (skrl) | skrl 2.1.1 SAC, 256 x 256 MLPs, 1-step returns, "
            "1000 steps | 0 | 0 % | 0 % | 100 % |") in text
    # The per-cell table of the PPO row pools both seeds (seed 1 failed the last 6 cells).
    ppo_cells = text.split("### rehab-knee-v2 / ppo (skrl)\n")[1]
    assert "| 1 | f160 | 2/2 | 2/2 | 2/2 | 2/2 | 2/2 |" in ppo_cells
    assert "| 1 | m185 |" + " 1/2 (1 cuff_force) |" * 5 in ppo_cells
    assert expert_calls == [("expert", ENV_ID)]
