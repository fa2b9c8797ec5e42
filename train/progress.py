"""A tqdm progress bar for stable-baselines3 training.

SB3's own ``progress_bar=True`` draws with ``tqdm.rich`` and so needs the ``rich`` package, which is not a
dependency here; ``TqdmProgressBar`` draws the same bar with plain tqdm (a core dependency).
"""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.callbacks import BaseCallback
from tqdm.auto import tqdm

__all__ = ["TqdmProgressBar"]


class TqdmProgressBar(BaseCallback):
    """Pass as ``callback=`` to ``model.learn``: one bar, in agent-steps, from 0 to ``total_timesteps``.

    SB3 collects whole rollouts, so training may run past ``total_timesteps``; the bar stops at its total.

    Args:
        desc: Text shown before the bar.
        **tqdm_kwargs: Extra keyword arguments of ``tqdm`` (e.g. ``file``, ``disable``, ``mininterval``).
    """

    def __init__(self, desc: str = "train", **tqdm_kwargs: Any) -> None:
        super().__init__()
        self.desc = desc
        self.tqdm_kwargs = tqdm_kwargs
        self.bar: tqdm | None = None

    def _on_training_start(self) -> None:
        # steps done by earlier learn() calls on the same model do not count
        total = int(self.locals["total_timesteps"]) - int(self.model.num_timesteps)
        self.bar = tqdm(total=max(total, 0), desc=self.desc, unit="step", **self.tqdm_kwargs)

    def _on_step(self) -> bool:
        # one call per env.step(), which advances every one of the vectorised envs
        if self.bar is not None:
            left = self.bar.total - self.bar.n
            if left > 0:
                self.bar.update(min(self.training_env.num_envs, left))
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
