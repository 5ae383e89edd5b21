"""Does an off-policy agent's critic rank the scripted expert's action above its reverse? A
diagnosis of SAC/TD3 runs that fail (README, Results, "Why SAC failed on SBX").

    python benchmarks/probes/critic_probe.py MODEL.zip [--episodes 2] [--seed 1000]

The scripted expert runs whole episodes of the model's env (its id and kwargs from the run's
manifest). In every state ``s`` it visits, the model's critic (the mean of its Q-networks) is
asked for ``Q(s, e)``, ``Q(s, -e)`` and ``Q(s, pi(s))``, where ``e`` is the expert's action and
``pi(s)`` the model's deterministic action. A critic that guides its actor towards the targets
ranks ``Q(s, e) > Q(s, -e)``. Printed per target of the exercise: the states, the share with
``Q(s, e) > Q(s, -e)``, the mean gap ``Q(s, e) - Q(s, -e)`` and the mean cosine between
``pi(s)`` and ``e``. SAC, TD3 and TQC models of either backend (SB3 or SBX; CrossQ on SB3)
not normalised.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict

import gymnasium as gym
import numpy as np

from rehabbot.common.text_tables import markdown_table
from rehabbot.rl.experts import ScriptedExpert
from rehabbot.rl.policies import env_for, load_policy

TINY = 1e-12


def _critic(model, backend: str):
    """``q(obs, actions_in_[-1, 1]) -> (n,)``: the mean over the model's Q-networks."""
    policy = model.policy
    if backend == "sbx":
        if not hasattr(policy, "qf_state") or getattr(policy.qf_state, "batch_stats", None):
            raise ValueError(f"critic_probe reads SBX's SAC, TD3 and TQC critics, not "
                             f"{type(model).__name__}'s")
        params = policy.qf_state.params

        def q(obs: np.ndarray, act: np.ndarray) -> np.ndarray:
            out = np.asarray(policy.qf.apply(params, obs, act))  # (critics, n, 1 or quantiles)
            return out.reshape(out.shape[0], len(obs), -1).mean(axis=(0, 2))
        return q
    import torch

    critic = getattr(policy, "critic", None)
    if critic is None:
        raise ValueError(f"{type(model).__name__} has no critic to probe (SAC, TD3, TQC, "
                         f"CrossQ only)")

    def q(obs: np.ndarray, act: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            values = critic(torch.as_tensor(obs), torch.as_tensor(act))
        stacked = torch.stack([v.reshape(len(obs), -1).mean(dim=1) for v in values])
        return stacked.mean(dim=0).numpy()
    return q


def probe(model_path: str, episodes: int, seed: int) -> list[dict]:
    """One row per (episode, target index): states, share ranked right, mean gap, cosine."""
    env_id, env_kwargs = env_for([model_path], None)
    env = gym.make(env_id, **env_kwargs)
    loaded = load_policy(model_path, env)
    if loaded.kind != "model" or loaded.vecnormalize is not None:
        raise ValueError("critic_probe needs a model file of a run without normalised "
                         "observations")
    model = loaded.policy
    q = _critic(model, loaded.backend)
    expert = ScriptedExpert(env)
    rows = []
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        states, targets, actions = [], [], []
        while True:
            states.append(obs)
            targets.append(int(info["target_index"]))
            action, _ = expert.predict(obs, deterministic=True)
            actions.append(action)
            obs, _r, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        obs_batch = np.asarray(states, dtype=np.float32)
        expert_act = np.stack([model.policy.scale_action(a) for a in actions]).astype(np.float32)
        policy_act = np.stack([model.policy.scale_action(model.predict(o, deterministic=True)[0])
                               for o in obs_batch]).astype(np.float32)
        gap = q(obs_batch, expert_act) - q(obs_batch, -expert_act)
        cosine = (policy_act * expert_act).sum(axis=1) / (
            np.linalg.norm(policy_act, axis=1) * np.linalg.norm(expert_act, axis=1) + TINY)
        by_target: dict[int, list[int]] = defaultdict(list)
        for i, t in enumerate(targets):
            by_target[t].append(i)
        for t, idx in sorted(by_target.items()):
            rows.append({"seed": seed + k, "exercise": int(info["exercise"]), "target": t,
                         "states": len(idx), "ranked_right": float(np.mean(gap[idx] > 0)),
                         "mean_gap": float(np.mean(gap[idx])),
                         "mean_cosine": float(np.mean(cosine[idx]))})
    env.close()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model.zip (or checkpoint) of an off-policy run")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1000, help="first episode seed (1000)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    try:
        rows = probe(args.model, args.episodes, args.seed)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(markdown_table(
        ["seed", "exercise", "target", "states", "Q(s,e) > Q(s,-e)", "mean Q(s,e) - Q(s,-e)",
         "mean cosine pi(s) to e"],
        [[r["seed"], r["exercise"], r["target"], r["states"], f"{100 * r['ranked_right']:.0f} %",
          f"{r['mean_gap']:.2f}", f"{r['mean_cosine']:.2f}"] for r in rows]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
