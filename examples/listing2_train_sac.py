"""The paper's Listing 2: train SAC on ``rehabbot/rehab-reach-v0`` with Stable-Baselines3's
defaults, logging to TensorBoard (``tensorboard --logdir UR5e_tensorboard``).

Two differences from the printed listing, both marked below:

* the ``evaluate_policy`` import is joined onto one line (the paper's typesetting broke it
  over two, which is a syntax error);
* one added last line saves the model as ``SAC-1.5M-R-2.5``, the file that Listing 3
  (``examples/listing3_evaluate_sac.py``) loads, so the two run one after the other
  (Stable-Baselines3 reads ``.5`` as the file's suffix, so it adds no ``.zip``).

200k steps take about an hour on one CPU core. For checkpoints, evaluation, several seeds
and a manifest, use ``rehabbot train rehab-reach-v0 --algo sac --hyperparams
sb3-defaults/sac`` (the same library defaults) instead.

Run it as ``OMP_NUM_THREADS=1 python examples/listing2_train_sac.py``: PyTorch trains this small
network faster on one CPU thread, and many times faster (14x measured) while other processes
share the cores.
"""

# The listing keeps the paper's import grouping and its unused import.
# ruff: noqa: I001, F401

import gymnasium as gym
from stable_baselines3 import SAC
from stable_baselines3.common.evaluation import evaluate_policy  # joined (see above)
import rehabbot

env = gym.make("rehabbot/rehab-reach-v0", render_mode=None)

model = SAC("MlpPolicy", env, verbose=1,
tensorboard_log="./UR5e_tensorboard/")
model.learn(total_timesteps=200_000)
model.save("SAC-1.5M-R-2.5")  # added: the model file Listing 3 loads
