"""What the skrl examples (``skrl_sac.py``, ``skrl_ppo.py``) share: quiet logging, their command
line, the trainer, the held-out evaluation over every profile x exercise x weight level and the
outputs.

The deterministic policy (the Gaussian's mean, clipped to the action box) runs
``--episodes-per-cell`` episodes of every cell, seeds counting up from 60 000 (away from the
training envs'). ``--out`` gets ``policy.pt`` (the policy's ``state_dict``) and ``result.json``
(the command, seed, settings, skrl version and every episode), which
``benchmarks/results/stratified_results.py --skrl`` renders as a row of its own.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shlex
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import skrl
import torch
from skrl.agents.torch import Agent
from skrl.envs.wrappers.torch import Wrapper
from skrl.models.torch import Model
from skrl.trainers.torch import SequentialTrainer, SequentialTrainerCfg

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


def parser(doc: str, *, timesteps: int, out: str) -> argparse.ArgumentParser:
    """The options of both examples; ``timesteps`` and ``out`` are the defaults."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--env", default="rehabbot/rehab-knee-v2")
    parser.add_argument("--timesteps", type=int, default=timesteps)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path(out))
    parser.add_argument("--episodes-per-cell", type=int, default=2)
    parser.add_argument("--max-episode-steps", type=int, default=None,
                        help="shorter episodes than the registered 1000 steps")
    return parser


def env_kwargs_of(args: argparse.Namespace) -> dict:
    return {} if args.max_episode_steps is None else {"max_episode_steps": args.max_episode_steps}


def train_agent(agent: Agent, env: Wrapper, timesteps: int) -> None:
    """skrl's sequential trainer: ``timesteps`` steps of ``env`` (no progress bar, rendering
    or TensorBoard), then the env is closed and the policy switched to evaluation mode."""
    cfg = SequentialTrainerCfg(timesteps=timesteps, headless=True, disable_progressbar=True,
                               close_environment_at_exit=False)
    SequentialTrainer(env=env, agents=agent, cfg=cfg).train()
    env.close()
    agent.policy.enable_training_mode(False)


@torch.inference_mode()
def deterministic_action(policy: Model, observation: np.ndarray) -> np.ndarray:
    """The Gaussian's mean action for one observation, clipped to [-1, 1]."""
    obs = torch.as_tensor(observation, dtype=torch.float32, device=policy.device).view(1, -1)
    _, outputs = policy.act({"observations": obs}, role="policy")
    return outputs["mean_actions"].clamp(-1.0, 1.0)[0].cpu().numpy()


def evaluate(policy: Model, env_id: str, *, episodes_per_cell: int = 2,
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


def evaluate_and_save(policy: Model, args: argparse.Namespace, argv: list[str], *, script: str,
                      start: float, train_seconds: float, **result) -> int:
    """Evaluate ``policy``, write ``policy.pt`` and ``result.json`` (with ``result``'s items:
    ``algo``, ``settings``, ``training``, ...) under ``args.out`` and print the summary."""
    evaluation = evaluate(policy, args.env, episodes_per_cell=args.episodes_per_cell,
                          env_kwargs=env_kwargs_of(args))
    args.out.mkdir(parents=True, exist_ok=True)
    weights = args.out / "policy.pt"
    torch.save(policy.state_dict(), weights.with_suffix(".pt.tmp"))
    os.replace(weights.with_suffix(".pt.tmp"), weights)
    result = {"command": shlex.join(["python", script, *argv]), "env": args.env,
              "env_kwargs": env_kwargs_of(args), "seed": args.seed, "timesteps": args.timesteps,
              **result, "train_seconds": round(train_seconds, 2),
              "wall_clock_seconds": round(time.perf_counter() - start, 2),
              "skrl_version": skrl.__version__, "evaluation": evaluation}
    (args.out / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    print_summary(evaluation)
    print(f"wrote {weights} and {args.out / 'result.json'}")
    return 0
