"""Reinforcement learning on the envs: training with Stable-Baselines3 (:mod:`.training`,
run folders in :mod:`.runs`, hyperparameter files in :mod:`.hyperparams`, shipped settings in
``hyperparams/``), running policies (:mod:`.policies`, :mod:`.rollout`), the scripted expert
(:mod:`.experts`) and the zoo of exported agents (:mod:`.zoo`, run with NumPy alone;
:mod:`.zoo_export` reads trained models). Agents are the libraries' own (SB3's and SBX's
``MlpPolicy``): what they need is in the observation of the ``-v2`` ids.

Stable-Baselines3 and PyTorch are imported only where a model is built or loaded.
"""
