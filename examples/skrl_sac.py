"""Train skrl's own SAC on a RehabBot ``-v2`` env, then evaluate it on held-out episodes.

    OMP_NUM_THREADS=1 python examples/skrl_sac.py [--env rehabbot/rehab-knee-v2]
        [--timesteps 100000] [--seed 0] [--out runs/skrl] [--episodes-per-cell 2]

OMP_NUM_THREADS=1 in front: PyTorch runs these small networks faster on one CPU thread, and
many times faster (14x measured) while other processes share the cores.

A Gaussian policy (tanh mean, state-independent log std, samples clipped to the action box)
and two Q critics with their targets, all 256x256 ReLU MLPs, with skrl's usual SAC settings
(learning rate 3e-4, batch 256, discount 0.99, polyak 0.005, learned entropy coefficient,
1000 random steps before the first update). The deterministic policy (the Gaussian's mean) is
then evaluated over every profile x exercise x weight level (``skrl_common.py``, shared with
``skrl_ppo.py``). Writes ``policy.pt`` (the policy's ``state_dict``) and ``result.json`` under
``--out``; no TensorBoard files or checkpoints. Needs ``pip install skrl`` (tested with skrl
2.1.1, PyTorch backend).
"""

from __future__ import annotations

import sys
import time

import gymnasium as gym
import skrl
import torch
from skrl.agents.torch.base import ExperimentCfg
from skrl.agents.torch.sac import SAC, SAC_CFG
from skrl.envs.wrappers.torch import wrap_env
from skrl.memories.torch import RandomMemory
from skrl.models.torch import DeterministicMixin, GaussianMixin, Model
from skrl.utils import set_seed
from skrl_common import env_kwargs_of, evaluate_and_save, parser, train_agent
from torch import nn

import rehabbot  # noqa: F401  (registers the rehabbot/* ids)


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
    train_agent(agent, env, timesteps)
    return agent


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    options = parser(__doc__, timesteps=100_000, out="runs/skrl")
    options.add_argument("--learning-starts", type=int, default=1000,
                         help="random steps before the first update")
    args = options.parse_args(argv)
    start = time.perf_counter()
    agent = train(args.env, args.timesteps, args.seed, learning_starts=args.learning_starts,
                  env_kwargs=env_kwargs_of(args))
    train_seconds = time.perf_counter() - start
    return evaluate_and_save(
        agent.policy, args, argv, script="examples/skrl_sac.py", start=start,
        train_seconds=train_seconds, algo="sac",
        training=f"skrl {skrl.__version__} SAC, 256 x 256 MLPs, 1-step returns, "
                 f"{args.timesteps} steps")


if __name__ == "__main__":
    sys.exit(main())
