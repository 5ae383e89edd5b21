"""Reinforcement learning on the envs: training with Stable-Baselines3 (:mod:`.training`,
run folders in :mod:`.runs`, hyperparameter files in :mod:`.hyperparams`, shipped settings in
``hyperparams/``), running policies (:mod:`.policies`, :mod:`.rollout`), the scripted expert
(:mod:`.experts`), the features extractor of our settings (:mod:`.features`, and its
NumPy twin :mod:`.features_numpy`) and the zoo of exported agents (:mod:`.zoo`, run with
NumPy alone; :mod:`.zoo_export` reads trained models).

Stable-Baselines3 and PyTorch are imported only where a model is built or loaded.
"""
