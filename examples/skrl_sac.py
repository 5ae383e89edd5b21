"""Train skrl's own SAC on a RehabBot ``-v2`` env, then evaluate it on held-out episodes.

    python examples/skrl_sac.py [--env rehabbot/rehab-knee-v2] [--timesteps 100000] [--seed 0]
                                [--out runs/skrl] [--episodes-per-cell 2]

A Gaussian policy (tanh mean, state-independent log std, samples clipped to the action box)
and two Q critics with their targets, all 256x256 ReLU MLPs, with skrl's usual SAC settings
(learning rate 3e-4, batch 256, discount 0.99, polyak 0.005, learned entropy coefficient,
1000 random steps before the first update). The deterministic policy (the Gaussian's mean) is
then evaluated over every profile x exercise x weight level. Writes ``policy.pt`` (the policy's
``state_dict``) and ``result.json`` under ``--out``; no TensorBoard files or checkpoints.
Needs ``pip install skrl`` (tested with skrl 2.1.1, PyTorch backend).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shlex
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import skrl
import torch
from skrl.agents.torch.base import ExperimentCfg
from skrl.agents.torch.sac import SAC, SAC_CFG
from skrl.envs.wrappers.torch import wrap_env
from skrl.memories.torch import RandomMemory
from skrl.models.torch import DeterministicMixin, GaussianMixin, Model
from skrl.trainers.torch import SequentialTrainer, SequentialTrainerCfg
from skrl.utils import set_seed
from torch import nn

import rehabbot  # noqa: F401  (registers the rehabbot/* ids)

# Quiet: skrl logs the seed, the wrapper, ... at INFO, and its Gymnasium wrapper warns that
# Gymnasium 1.x has no ``gymnasium.experimental`` (harmless).
skrl.logger.setLevel(logging.WARNING)
skrl.logger.addFilter(lambda record: "gymnasium.experimental" not in record.getMessage())

# None: the default patient (1.75 m, 75 kg, male).
PROFILES = (None, {"height_m": 1.60, "mass_kg": 60.0, "sex": "female"},
            {"height_m": 1.85, "mass_kg": 90.0, "sex": "male"})
WEIGHT_LEVELS = range(5)
FIRST_EVAL_SEED = 60000  # evaluation seeds, away from the training env's


def mlp(n_in: int, n_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(n_in, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(),
                         nn.Linear(256, n_out))


class Policy(GaussianMixin, Model):
    """Gaussian policy: tanh mean, a learned state-independent log std."""

    def __init__(self, observation_space, action_space, device=None):
        Model.__init__(self, observation_space=observation_space, action_space=action_space,
                       device=device)
        GaussianMixin.__init__(self, clip_actions=True, clip_log_std=True, min_log_std=-5,
                               max_log_std=2, reduction="sum")
        self.net = mlp(self.num_observations, self.num_actions)
        self.log_std_parameter = nn.Parameter(torch.zeros(self.num_actions))

    def compute(self, inputs, role=""):
        return torch.tanh(self.net(inputs["observations"])), {"log_std": self.log_std_parameter}

    def random_act(self, inputs, role=""):
        # skrl 2.1.1's Model.random_act repeats one action on every call with Gymnasium 1.x
        # (skrl issue #453); draw uniformly from the [-1, 1] box with torch's seeded RNG instead.
        n = inputs["observations"].shape[0]
        return 2 * torch.rand(n, self.num_actions, device=self.device) - 1, {}


class Critic(DeterministicMixin, Model):
    """Q(observation, action)."""

    def __init__(self, observation_space, action_space, device=None):
        Model.__init__(self, observation_space=observation_space, action_space=action_space,
                       device=device)
        DeterministicMixin.__init__(self, clip_actions=False)
        self.net = mlp(self.num_observations + self.num_actions, 1)

    def compute(self, inputs, role=""):
        x = torch.cat([inputs["observations"], inputs["taken_actions"]], dim=-1)
        return self.net(x), {}


def train(env_id: str, timesteps: int, seed: int, *, learning_starts: int = 1000,
          env_kwargs: dict | None = None, device: str | None = None) -> SAC:
    """Train SAC for ``timesteps`` steps; the trained policy is ``agent.policy``."""
    set_seed(seed)  # random, numpy, torch, and the seed of wrap_env's first env.reset
    env = wrap_env(gym.make(env_id, **(env_kwargs or {})), wrapper="gymnasium", verbose=False)
    obs_space, act_space, device = env.observation_space, env.action_space, env.device
    models = {"policy": Policy(obs_space, act_space, device)}
    for name in ("critic_1", "critic_2", "target_critic_1", "target_critic_2"):
        models[name] = Critic(obs_space, act_space, device)
    cfg = SAC_CFG(learning_rate=3e-4, batch_size=256, discount_factor=0.99, polyak=0.005,
                  learn_entropy=True, random_timesteps=learning_starts,
                  learning_starts=learning_starts,
                  experiment=ExperimentCfg(write_interval=0, checkpoint_interval=0))
    memory = RandomMemory(memory_size=max(timesteps, 1), num_envs=env.num_envs, device=device)
    agent = SAC(models=models, memory=memory, observation_space=obs_space,
                action_space=act_space, device=device, cfg=cfg)
    trainer_cfg = SequentialTrainerCfg(timesteps=timesteps, headless=True,
                                       disable_progressbar=True, close_environment_at_exit=False)
    SequentialTrainer(env=env, agents=agent, cfg=trainer_cfg).train()
    env.close()
    agent.policy.enable_training_mode(False)
    return agent


@torch.inference_mode()
def deterministic_action(policy: Policy, observation: np.ndarray) -> np.ndarray:
    """The Gaussian's mean action for one observation, clipped to [-1, 1]."""
    obs = torch.as_tensor(observation, dtype=torch.float32, device=policy.device).view(1, -1)
    _, outputs = policy.act({"observations": obs}, role="policy")
    return outputs["mean_actions"].clamp(-1.0, 1.0)[0].cpu().numpy()


def evaluate(policy: Policy, env_id: str, *, episodes_per_cell: int = 2,
             env_kwargs: dict | None = None) -> dict:
    """Deterministic episodes over every profile x exercise x weight level."""
    episodes, seed = [], FIRST_EVAL_SEED
    for profile in PROFILES:
        kwargs = dict(env_kwargs or {}, **({} if profile is None else {"profile": profile}))
        env = gym.make(env_id, **kwargs)
        for exercise in range(len(env.unwrapped.targets)):
            for level in WEIGHT_LEVELS:
                for _ in range(episodes_per_cell):
                    obs, _ = env.reset(seed=seed, options={"exercise": exercise,
                                                           "weight_level": level})
                    done = False
                    while not done:
                        obs, _, terminated, truncated, info = env.step(
                            deterministic_action(policy, obs))
                        done = terminated or truncated
                    episodes.append({"seed": seed, "profile": profile, "exercise": exercise,
                                     "weight_level": level, "success": bool(info["is_success"]),
                                     "safety_violation": info["safety_violation"]})
                    seed += 1
        env.close()
    rate = float(np.mean([e["success"] for e in episodes]))
    return {"success_rate": rate, "episodes": episodes}


def print_summary(evaluation: dict) -> None:
    episodes = evaluation["episodes"]
    print(f"success rate: {evaluation['success_rate']:.3f} ({len(episodes)} episodes)")
    for profile in PROFILES:
        name = "default" if profile is None else f"{profile['sex']} {profile['height_m']} m"
        for exercise in sorted({e["exercise"] for e in episodes}):
            cells = [[e["success"] for e in episodes if e["profile"] == profile
                      and e["exercise"] == exercise and e["weight_level"] == level]
                     for level in WEIGHT_LEVELS]
            counts = "  ".join(f"L{lv} {sum(c)}/{len(c)}" for lv, c in enumerate(cells))
            print(f"  {name:<16} exercise {exercise}: {counts}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="rehabbot/rehab-knee-v2")
    parser.add_argument("--timesteps", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("runs/skrl"))
    parser.add_argument("--episodes-per-cell", type=int, default=2)
    parser.add_argument("--learning-starts", type=int, default=1000,
                        help="random steps before the first update")
    parser.add_argument("--max-episode-steps", type=int, default=None,
                        help="shorter episodes than the registered 1000 steps")
    args = parser.parse_args(argv)
    env_kwargs = {} if args.max_episode_steps is None else {
        "max_episode_steps": args.max_episode_steps}

    start = time.perf_counter()
    agent = train(args.env, args.timesteps, args.seed, learning_starts=args.learning_starts,
                  env_kwargs=env_kwargs)
    train_seconds = time.perf_counter() - start
    evaluation = evaluate(agent.policy, args.env, episodes_per_cell=args.episodes_per_cell,
                          env_kwargs=env_kwargs)

    args.out.mkdir(parents=True, exist_ok=True)
    weights = args.out / "policy.pt"
    torch.save(agent.policy.state_dict(), weights.with_suffix(".pt.tmp"))
    os.replace(weights.with_suffix(".pt.tmp"), weights)
    result = {"command": shlex.join(["python", "examples/skrl_sac.py", *argv]),
              "env": args.env, "env_kwargs": env_kwargs, "seed": args.seed,
              "timesteps": args.timesteps, "train_seconds": round(train_seconds, 2),
              "wall_clock_seconds": round(time.perf_counter() - start, 2),
              "skrl_version": skrl.__version__, "evaluation": evaluation}
    (args.out / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    print_summary(evaluation)
    print(f"wrote {weights} and {args.out / 'result.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
