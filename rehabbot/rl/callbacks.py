"""Stable-Baselines3 callbacks of a training run: atomic checkpoints with the newest replay
buffer only, and a stopper for signals and for PPO's exact step count. Defined on first use,
so that importing this module does not import Stable-Baselines3."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rehabbot.common.files import atomic_write
from rehabbot.rl import runs
from rehabbot.rl.replay_buffer_io import save_replay_buffer
from rehabbot.rl.safe_load import save_model
from rehabbot.rl.vecnormalize_io import save_vecnormalize


@functools.cache
def callback_classes() -> tuple[type, type]:
    """SB3 callback subclasses, defined lazily so that SB3 is imported only when training."""
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class Checkpointer(CheckpointCallback):
        """SB3's CheckpointCallback with atomic files, the newest replay buffer kept only
        (its filled part, :mod:`rehabbot.rl.replay_buffer_io`), and a hook that updates the
        manifest."""

        def __init__(self, save_freq: int, save_path: str,
                     on_saved: Callable[[int, Path], None]) -> None:
            super().__init__(save_freq, save_path, name_prefix=runs.CHECKPOINT_PREFIX,
                             save_replay_buffer=True, save_vecnormalize=True, verbose=0)
            self.on_saved = on_saved
            self.last_saved: tuple[int, Path] | None = None

        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq == 0:
                self.save_now()
            return True

        def save_now(self) -> Path:
            steps = int(self.model.num_timesteps)
            if self.last_saved is not None and self.last_saved[0] == steps:
                return self.last_saved[1]
            folder = Path(self.save_path)
            folder.mkdir(parents=True, exist_ok=True)
            replay_path, vecnormalize_path = runs.companions(folder, steps)
            if getattr(self.model, "replay_buffer", None) is not None:
                atomic_write(replay_path,
                             lambda stream: save_replay_buffer(self.model, stream))
            vec_normalize = self.model.get_vec_normalize_env()
            if vec_normalize is not None:
                save_vecnormalize(vec_normalize, vecnormalize_path)
            model_path = folder / f"{runs.CHECKPOINT_PREFIX}_{steps}_steps.zip"
            # last: a zip marks a full checkpoint
            atomic_write(model_path, lambda stream: save_model(self.model, stream))
            for old in folder.glob(f"{runs.CHECKPOINT_PREFIX}_replay_buffer_*_steps.npz"):
                if old != replay_path:
                    with contextlib.suppress(OSError):
                        old.unlink()
            self.last_saved = (steps, model_path)
            self.on_saved(steps, model_path)
            return model_path

    class Stopper(BaseCallback):
        """Stops ``learn`` once ``latch`` (a :class:`~rehabbot.common.signals.SignalLatch`)
        holds a signal, and PPO exactly at the requested step count."""

        def __init__(self, target: int, exact_rollouts: bool, latch: Any) -> None:
            super().__init__(verbose=0)
            self.target = target
            self.exact_rollouts = exact_rollouts
            self.latch = latch

        def _on_step(self) -> bool:
            if self.latch.signum is not None:
                return False
            if self.exact_rollouts and self.model.num_timesteps >= self.target:
                n_steps, n_rollout = self.locals.get("n_steps"), self.locals.get(
                    "n_rollout_steps")
                # A rollout that is about to fill up is trained on; a partial one is dropped.
                if n_steps is not None and n_rollout is not None and n_steps + 1 < n_rollout:
                    return False
            return True

    return Checkpointer, Stopper
