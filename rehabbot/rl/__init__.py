"""Reinforcement learning on the envs: training with Stable-Baselines3 (:mod:`.training`,
run folders in :mod:`.runs`, hyperparameter files in :mod:`.hyperparams`, shipped settings in
``hyperparams/``), running policies (:mod:`.policies`, :mod:`.rollout`), the scripted expert
(:mod:`.experts`) and the features extractor of our settings (:mod:`.features`).

Stable-Baselines3 and PyTorch are imported only where a model is built or loaded.
"""
