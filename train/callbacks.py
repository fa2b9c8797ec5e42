"""What ``agentsim train`` does while PPO learns: a progress bar with the live mean return, the learning curve
(CSV, one row per rollout) and checkpoints every N agent-steps.

SB3's own ``progress_bar=True`` draws with ``tqdm.rich`` and so needs ``rich``, which is not a dependency: the bar
here is plain tqdm. Episode returns come from SB3's episode buffer (``model.ep_info_buffer``: the last 100
finished agent-episodes, filled from the ``episode`` entries of the VecEnv's infos).
"""

from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from tqdm.auto import tqdm

from agentsim_env.train.checkpoints import write_json_atomic, write_model_atomic

__all__ = ["CURVE_FIELDS", "TrainMonitor", "read_curve"]

#: Columns of ``curve.csv``.
CURVE_FIELDS = ("timesteps", "episodes", "mean_return", "mean_length", "wall_s", "cpu_s")


def read_curve(path: str | Path) -> list[dict[str, float]]:
    """Rows of a ``curve.csv`` (numbers as floats; ``mean_return`` is NaN before the first finished episode)."""
    with open(path, newline="", encoding="utf-8") as f:
        return [{k: float(v) if v != "" else float("nan") for k, v in row.items()} for row in csv.DictReader(f)]


class TrainMonitor(BaseCallback):
    """Pass as ``callback=`` to ``model.learn``.

    Args:
        out: Run folder: ``curve.csv`` and ``checkpoints/step_<N>.zip`` are written there (``None``: nothing).
        checkpoint_every: Agent-steps between checkpoints (0: none).
        progress: Show the bar (on stderr).
        desc: Text before the bar.
        start_wall: Wall and CPU seconds already spent (a resumed run continues its clocks).
        start_cpu: See ``start_wall``.
        episodes_done: Agent-episodes finished before (a resumed run).
    """

    def __init__(
        self,
        out: str | Path | None,
        *,
        checkpoint_every: int = 0,
        progress: bool = True,
        desc: str = "train",
        start_wall: float = 0.0,
        start_cpu: float = 0.0,
        episodes_done: int = 0,
    ) -> None:
        super().__init__()
        self.out = None if out is None else Path(out)
        self.checkpoint_every = int(checkpoint_every)
        self.progress = progress
        self.desc = desc
        self.bar: tqdm | None = None
        self.episodes = int(episodes_done)
        self._wall0 = self._cpu0 = 0.0
        self._start_wall, self._start_cpu = start_wall, start_cpu
        self._next_ckpt = 0
        self.checkpoints: list[Path] = []

    # clocks -------------------------------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        """Whether ``learn`` started (the clocks run)."""
        return self._wall0 > 0.0

    def wall_s(self) -> float:
        """Wall seconds of training so far (this run and what it resumed)."""
        return self._start_wall + time.perf_counter() - self._wall0

    def cpu_s(self) -> float:
        """Process CPU seconds of training so far."""
        return self._start_cpu + time.process_time() - self._cpu0

    def mean_return(self) -> float:
        """Mean return of the last (up to) 100 finished agent-episodes (NaN before the first)."""
        buf = self.model.ep_info_buffer
        return float(np.mean([e["r"] for e in buf])) if buf else float("nan")

    # SB3 hooks ----------------------------------------------------------------------------------------------
    def _on_training_start(self) -> None:
        self._wall0, self._cpu0 = time.perf_counter(), time.process_time()
        done = int(self.model.num_timesteps)
        total = int(self.locals["total_timesteps"])  # SB3 adds the steps already done when resuming
        if self.checkpoint_every:
            self._next_ckpt = (done // self.checkpoint_every + 1) * self.checkpoint_every
        if self.progress:
            self.bar = tqdm(total=total, initial=min(done, total), desc=self.desc, unit="step", smoothing=0.1)
        if self.out is not None and not (self.out / "curve.csv").exists():
            with open(self.out / "curve.csv", "w", newline="", encoding="utf-8") as f:
                csv.writer(f).writerow(CURVE_FIELDS)

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            if "episode" in info:
                self.episodes += 1
        if self.bar is not None:
            left = self.bar.total - self.bar.n
            if left > 0:
                self.bar.update(min(self.training_env.num_envs, left))
        if self.checkpoint_every and self.num_timesteps >= self._next_ckpt and self.out is not None:
            self.save_checkpoint()
            while self._next_ckpt <= self.num_timesteps:
                self._next_ckpt += self.checkpoint_every
        return True

    def _on_rollout_end(self) -> None:
        ret = self.mean_return()
        if self.bar is not None:
            self.bar.set_postfix_str(f"return {ret:.2f}  episodes {self.episodes}", refresh=False)
        if self.out is not None:
            lens = [e["l"] for e in self.model.ep_info_buffer or ()]
            row = (
                self.num_timesteps,
                self.episodes,
                "" if np.isnan(ret) else f"{ret:.6g}",
                f"{np.mean(lens):.6g}" if lens else "",
                f"{self.wall_s():.3f}",
                f"{self.cpu_s():.3f}",
            )
            with open(self.out / "curve.csv", "a", newline="", encoding="utf-8") as f:
                csv.writer(f).writerow(row)

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def save_checkpoint(self) -> Path | None:
        """Save the model (weights, optimiser, step count) as ``checkpoints/step_<N>.zip`` with the clocks.

        Both files are written atomically, the clocks first, so a crash at any moment leaves no partial
        checkpoint and no checkpoint without its clocks (see ``agentsim_env.train.checkpoints``).

        Returns:
            The checkpoint, or ``None`` when a folder or other non-file holds its name (said on stderr; training
            goes on and the next checkpoint is written as usual).
        """
        assert self.out is not None
        folder = self.out / "checkpoints"
        folder.mkdir(exist_ok=True)
        path = folder / f"step_{self.num_timesteps}.zip"
        sidecar = path.with_suffix(".json")
        taken = [p for p in (path, sidecar) if (p.exists() or p.is_symlink()) and not p.is_file()]
        if taken:
            print(f"checkpoint {path.name} not written: {str(taken[0])!r} is not a file", file=sys.stderr)
            return None
        clocks = {"wall_s": self.wall_s(), "cpu_s": self.cpu_s(), "episodes": self.episodes}
        write_json_atomic(sidecar, clocks)
        write_model_atomic(self.model, path)
        self.checkpoints.append(path)
        return path
