"""examples/skrl_sac.py: a tiny run of skrl's SAC, its stratified evaluation and its outputs."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skrl")
torch = pytest.importorskip("torch")
gym = pytest.importorskip("gymnasium")

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "skrl_sac.py"
ENV_ID = "rehabbot/rehab-knee-v2"


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("skrl_sac_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_train_evaluate_save(example, tmp_path, monkeypatch, capsys):
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

    result = json.loads((out / "result.json").read_text())
    assert result["seed"] == 3 and result["timesteps"] == 300
    assert result["command"].startswith("python examples/skrl_sac.py")
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
    assert [e["profile"] for e in episodes[::10]] == [None, *example.PROFILES[1:]]
    rate = np.mean([e["success"] for e in episodes])
    assert result["evaluation"]["success_rate"] == pytest.approx(rate)
    assert not (out / "policy.pt.tmp").exists()

    # SAC updated (the learned entropy coefficient left its initial 0.2), and the saved weights
    # load into a fresh policy that acts as the trained one.
    assert trained["agent"].log_entropy_coefficient.exp().item() != pytest.approx(0.2)
    policy = trained["agent"].policy
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    fresh = example.Policy(env.observation_space, env.action_space, device="cpu")
    fresh.load_state_dict(torch.load(out / "policy.pt", map_location="cpu", weights_only=True))
    fresh.enable_training_mode(False)
    action = example.deterministic_action(fresh, obs)
    np.testing.assert_allclose(action, example.deterministic_action(policy, obs), atol=1e-5)
    assert action.shape == (6,) and np.all(np.abs(action) <= 1.0)
    # Sampled (stochastic) and random exploration actions stay in the box too.
    batch = torch.as_tensor(np.stack([obs] * 64), dtype=torch.float32)
    with torch.no_grad():
        sampled, _ = fresh.act({"observations": batch}, role="policy")
        random, _ = fresh.random_act({"observations": batch}, role="policy")
    assert sampled.abs().max() <= 1.0 and random.abs().max() <= 1.0
    assert not torch.equal(random[0], random[1])  # skrl issue #453: one repeated action
    env.close()
