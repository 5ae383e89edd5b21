"""The paper's Listing 3: load a trained SAC model and evaluate it for 5 episodes with
Stable-Baselines3's ``evaluate_policy``.

It loads the file ``SAC-1.5M-R-2.5`` (no ``.zip``: SB3 reads ``.5`` as its suffix) from the
working folder, which Listing 2 (``examples/listing2_train_sac.py``) saves; a model trained
by ``rehabbot train`` works too:
``cp runs/rehab-reach-v0/sac/seed0/model.zip SAC-1.5M-R-2.5``.

Two differences from the printed listing, both marked below: the ``evaluate_policy`` import
is joined onto one line, and the printed call ``evaluate_policy(model, model.get_env()),
n_eval_episodes=5)`` had one closing parenthesis too many (a syntax error), removed here.
For success rates, safety events and smoothness metrics, use ``rehabbot evaluate``.

Run it as ``OMP_NUM_THREADS=1 python examples/listing3_evaluate_sac.py``: PyTorch evaluates
this small network faster on one CPU thread, and many times faster (14x measured) while
other processes share the cores.
"""

# The listing keeps the paper's import grouping and its unused import.
# ruff: noqa: I001, F401

import gymnasium as gym
from stable_baselines3 import SAC
from stable_baselines3.common.evaluation import evaluate_policy  # joined (see above)
import rehabbot

env = gym.make("rehabbot/rehab-reach-v0", render_mode=None)

model = SAC.load("SAC-1.5M-R-2.5", env=env,
print_system_info=True)

mean_reward, std_reward = evaluate_policy(model, model.get_env(),  # one ")" removed
n_eval_episodes=5)

print(f"Mean reward: {mean_reward:.2f} ± {std_reward:.2f}")
