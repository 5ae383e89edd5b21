"""Train skrl's own PPO on a RehabBot ``-v2`` env, then evaluate it on held-out episodes.

    OMP_NUM_THREADS=1 python examples/skrl_ppo.py [--env rehabbot/rehab-knee-v2]
        [--timesteps 1000000] [--seed 0] [--out runs/skrl-ppo] [--episodes-per-cell 2]

OMP_NUM_THREADS=1 in front: PyTorch runs these small networks faster on one CPU thread, and
many times faster (14x measured) while other processes share the cores.

The settings of RehabBot's own PPO runs on the ``-v2`` ids (``rehabbot/rl/hyperparams/ppo.yml``:
Stable-Baselines3's PPO defaults with 8 envs x 256 steps per update, a learning rate falling
linearly from 3e-4 to 0 and a Gaussian whose state-independent log std starts at -1), in skrl:
separate 64 x 64 tanh MLPs for the policy and the value, orthogonal initialisation, 10 epochs of
32 mini-batches of 64, discount 0.99, GAE lambda 0.95, ratio clip 0.2, value loss x 0.5 (not
clipped), gradient norm clip 0.5, no entropy bonus, no observation or reward scaling. The
Gaussian's samples are stored as drawn and clipped to the action box on their way into the env.
The deterministic policy (the Gaussian's mean) is then evaluated over every profile x exercise x
weight level (``skrl_common.py``, shared with ``skrl_sac.py``). Writes ``policy.pt`` (the
policy's ``state_dict``) and ``result.json`` (with the learning curve) under ``--out``; no
TensorBoard files or checkpoints. Needs ``pip install skrl`` (tested with skrl 2.1.1, PyTorch).
"""

from __future__ import annotations

import math
import sys
import time

import gymnasium as gym
import numpy as np
import skrl
import torch
from skrl.agents.torch.base import ExperimentCfg
from skrl.agents.torch.ppo import PPO, PPO_CFG
from skrl.envs.wrappers.torch import wrap_env
from skrl.memories.torch import RandomMemory
from skrl.models.torch import DeterministicMixin, GaussianMixin, Model
from skrl.utils import set_seed
from skrl_common import env_kwargs_of, evaluate_and_save, parser, train_agent
from torch import nn

import rehabbot  # noqa: F401  (registers the rehabbot/* ids)

SETTINGS = {"n_envs": 8, "rollouts": 256, "learning_epochs": 10, "mini_batches": 32,
            "discount_factor": 0.99, "gae_lambda": 0.95, "learning_rate": 3e-4,
            "learning_rate_schedule": "linear to 0", "adam_eps": 1e-5, "ratio_clip": 0.2,
            "value_clip": 0.0, "value_loss_scale": 0.5, "entropy_loss_scale": 0.0,
            "grad_norm_clip": 0.5, "hidden": [64, 64], "activation": "tanh",
            "log_std_init": -1.0}
REPORT_EVERY = 20  # updates per row of the learning curve (20 x 2048 = 40 960 steps)


def mlp(n_in: int, n_out: int, out_gain: float) -> nn.Sequential:
    """64 x 64 tanh, orthogonal weights (gain sqrt 2; ``out_gain`` for the last layer), zero
    biases: Stable-Baselines3's initialisation."""
    layers = [nn.Linear(n_in, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, n_out)]
    for layer, gain in zip(layers[::2], (math.sqrt(2), math.sqrt(2), out_gain), strict=True):
        nn.init.orthogonal_(layer.weight, gain)
        nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


class Policy(GaussianMixin, Model):
    """Gaussian policy: a linear mean and a learned state-independent log std. The samples are
    not clipped here: PPO keeps the action it drew (and its log-probability), and the env's
    ``ClipAction`` wrapper clips what reaches the robot, as Stable-Baselines3 does."""

    def __init__(self, observation_space, action_space, device=None):
        Model.__init__(self, observation_space=observation_space, action_space=action_space,
                       device=device)
        GaussianMixin.__init__(self, clip_actions=False, reduction="sum")
        self.net = mlp(self.num_observations, self.num_actions, out_gain=0.01)
        self.log_std_parameter = nn.Parameter(
            torch.full((self.num_actions,), SETTINGS["log_std_init"]))

    def compute(self, inputs, role=""):
        return self.net(inputs["observations"]), {"log_std": self.log_std_parameter}


class Value(DeterministicMixin, Model):
    """V(observation)."""

    def __init__(self, observation_space, action_space, device=None):
        Model.__init__(self, observation_space=observation_space, action_space=action_space,
                       device=device)
        DeterministicMixin.__init__(self, clip_actions=False)
        self.net = mlp(self.num_observations, 1, out_gain=1.0)

    def compute(self, inputs, role=""):
        return self.net(inputs["observations"]), {}


class EpisodeEndPPO(PPO):
    """skrl's PPO, told where episodes end in a Gymnasium 1.x vector env, and keeping a
    learning curve.

    skrl 2.1.1 does not know Gymnasium 1.x's autoreset modes. The vector env here resets an
    ended episode within the step (``SAME_STEP``), so the step's observation is already the
    next episode's first one and the last one is in ``info["final_obs"]``. With
    ``time_limit_bootstrap=True`` skrl ends GAE at every episode end and bootstraps a truncated
    step with the value of its next observation: that must be the episode's last observation,
    not the next episode's first. (With the default ``NEXT_STEP`` mode skrl would instead
    train on one extra step per episode whose action the env ignores, leading from the last
    observation to the next episode's first, and carry GAE across; with
    ``time_limit_bootstrap=False`` it carries GAE across truncations in either mode.) A step
    that both terminates and truncates is a termination (no bootstrap)."""

    def init(self, *, trainer_cfg=None) -> None:
        super().init(trainer_cfg=trainer_cfg)
        self.episodes: list[tuple[float, int, bool]] = []  # (return, length, success)
        self.curve: list[dict] = []
        self.updates = 0

    def record_transition(self, *, next_observations, terminated, truncated, infos, **kwargs):
        ended = (terminated | truncated).view(-1).cpu().numpy()
        if self.training and ended.any():
            next_observations = next_observations.clone()
            next_observations[ended] = torch.as_tensor(
                np.stack(infos["final_obs"][ended]), dtype=torch.float32, device=self.device)
            self.episodes += zip(infos["episode"]["r"][ended].tolist(),
                                 infos["episode"]["l"][ended].tolist(),
                                 infos["final_info"]["is_success"][ended].tolist(), strict=True)
        super().record_transition(next_observations=next_observations, terminated=terminated,
                                  truncated=truncated & ~terminated, infos=infos, **kwargs)

    def update(self, *, timestep: int, timesteps: int) -> None:
        super().update(timestep=timestep, timesteps=timesteps)
        self.updates += 1
        if self.updates % REPORT_EVERY and timestep + 1 + self.cfg.rollouts <= timesteps:
            return  # a row every REPORT_EVERY updates and after the last
        data, n = self.tracking_data, self.updates - REPORT_EVERY * len(self.curve)
        episodes = np.array(self.episodes, dtype=float).reshape(-1, 3)
        ret, length, success = (float(c.mean()) if len(c) else None for c in episodes.T)
        row = {"steps": (timestep + 1) * self.memory.num_envs, "episodes": len(episodes),
               "success": success, "return": ret, "length": length,
               "value_loss": float(np.mean(data["Loss / Value loss"][-n:])),
               "std": data["Policy / Standard deviation"][-1],
               "learning_rate": data["Learning / Learning rate"][-1]}
        self.curve.append(row)
        self.episodes = []
        print(f"{row['steps']:>8} steps: {row['episodes']:>3} episodes, success "
              f"{row['success'] or 0:.2f}, return {row['return'] or 0:7.1f}, length "
              f"{row['length'] or 0:6.1f}, value loss {row['value_loss']:8.3f}, "
              f"std {row['std']:.3f}", flush=True)


def make_env(env_id: str, env_kwargs: dict | None = None):
    """``n_envs`` copies in a Gymnasium vector env (same-step autoreset, episode statistics in
    ``info["episode"]``, actions clipped to the box), wrapped for skrl."""
    envs = gym.vector.SyncVectorEnv(
        [lambda: gym.make(env_id, **(env_kwargs or {}))] * SETTINGS["n_envs"],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    envs = gym.wrappers.vector.RecordEpisodeStatistics(gym.wrappers.vector.ClipAction(envs))
    return wrap_env(envs, wrapper="gymnasium", verbose=False)


def make_agent(env, timesteps: int, device: str | None = None) -> EpisodeEndPPO:
    """PPO with SETTINGS for ``env`` (from :func:`make_env`), its learning rate falling
    linearly to 0 over ``timesteps`` env steps in all."""
    obs_space, act_space, device = env.observation_space, env.action_space, device or env.device
    s = SETTINGS
    # skrl steps the scheduler after every learning epoch: it falls to 0 over all of them.
    n_epochs = max(timesteps // env.num_envs // s["rollouts"], 1) * s["learning_epochs"]
    cfg = PPO_CFG(
        rollouts=s["rollouts"], learning_epochs=s["learning_epochs"],
        mini_batches=s["mini_batches"], discount_factor=s["discount_factor"],
        gae_lambda=s["gae_lambda"], learning_rate=s["learning_rate"],
        learning_rate_scheduler=torch.optim.lr_scheduler.LinearLR,
        learning_rate_scheduler_kwargs={"start_factor": 1.0, "end_factor": 0.0,
                                        "total_iters": n_epochs},
        ratio_clip=s["ratio_clip"], value_clip=s["value_clip"],
        value_loss_scale=s["value_loss_scale"], entropy_loss_scale=s["entropy_loss_scale"],
        grad_norm_clip=s["grad_norm_clip"], time_limit_bootstrap=True,
        experiment=ExperimentCfg(write_interval=0, checkpoint_interval=0))
    models = {"policy": Policy(obs_space, act_space, device),
              "value": Value(obs_space, act_space, device)}
    memory = RandomMemory(memory_size=s["rollouts"], num_envs=env.num_envs, device=device)
    agent = EpisodeEndPPO(models=models, memory=memory, observation_space=obs_space,
                          action_space=act_space, device=device, cfg=cfg)
    for group in agent.optimizer.param_groups:  # Adam's epsilon as in Stable-Baselines3
        group["eps"] = s["adam_eps"]
    return agent


def train(env_id: str, timesteps: int, seed: int, *,
          env_kwargs: dict | None = None) -> EpisodeEndPPO:
    """Train PPO for ``timesteps`` env steps in all; the trained policy is ``agent.policy``."""
    set_seed(seed)  # random, numpy, torch, and the seed of the vector env's first reset
    env = make_env(env_id, env_kwargs)
    agent = make_agent(env, timesteps)
    train_agent(agent, env, timesteps // env.num_envs)  # skrl counts steps of the vector env
    return agent


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser(__doc__, timesteps=1_000_000, out="runs/skrl-ppo").parse_args(argv)
    start = time.perf_counter()
    agent = train(args.env, args.timesteps, args.seed, env_kwargs=env_kwargs_of(args))
    train_seconds = time.perf_counter() - start
    s = SETTINGS
    return evaluate_and_save(
        agent.policy, args, argv, script="examples/skrl_ppo.py", start=start,
        train_seconds=train_seconds, algo="ppo", settings=SETTINGS,
        training=f"skrl {skrl.__version__} PPO, 64 x 64 tanh MLPs, {s['n_envs']} envs x "
                 f"{s['rollouts']} steps per update, {args.timesteps} steps",
        steps_per_second=round(args.timesteps / train_seconds, 1), learning_curve=agent.curve)


if __name__ == "__main__":
    sys.exit(main())
