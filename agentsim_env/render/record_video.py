"""``RecordVideo``: a ParallelEnv wrapper that films chosen episodes, like Gymnasium's ``RecordVideo``.

The wrapped env must be built with ``render_mode="rgb_array"``. Episode ``k`` (the ``k``-th ``reset``, from 0) is
filmed when ``episode_trigger(k)`` is true (default: every ``every_n``-th episode, 0 included): the frame after
the reset and one after every step go to ``{video_folder}/{name_prefix}-episode-{k}.{fmt}``, written when all
agents are done, at the next ``reset`` (an episode cut short) or on ``close``. MP4 frames stream to ffmpeg as they
come; GIF frames are kept (8-bit) until the file is written. Videos need the ``video`` extra
(``pip install "agentsim-env[video]"``), checked when the wrapper is built.

Everything else (spaces, agents, ``state``, the env's own methods) is the wrapped env's, forwarded by the base
``agentsim_env.wrappers.ParallelEnvWrapper``, so the wrapper is a PettingZoo ``ParallelEnv`` that runs anywhere the
env does. ``rollout`` is the wrapped env's: it runs on arrays and renders no frames.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pettingzoo.utils.env import ParallelEnv

from agentsim_env.render.video import VIDEO_FORMATS, VideoWriter, check_video_support
from agentsim_env.wrappers import ParallelEnvWrapper

__all__ = ["RecordVideo"]


class RecordVideo(ParallelEnvWrapper):
    """Film the episodes of a ``ParallelEnv`` that ``episode_trigger`` picks.

    Args:
        env: An env built with ``render_mode="rgb_array"`` (its ``render()`` returns an RGB frame), or a
            wrapper of one.
        video_folder: Folder of the videos (created when missing).
        episode_trigger: ``f(k) -> bool`` over episode numbers (0, 1, ...); None: every ``every_n``-th episode.
        every_n: The period of the default trigger (episodes 0, every_n, 2 * every_n, ...), >= 1.
        name_prefix: File name prefix: ``{name_prefix}-episode-{k}.{fmt}``.
        fps: Frames per second of the videos (None: ``env.metadata["render_fps"]``, else 30).
        fmt: ``"mp4"`` or ``"gif"``.

    Attributes:
        episode: Number of the current episode (-1 before the first reset).
        written: Paths of the videos written so far, in order.

    Raises:
        ValueError: For an env without ``render_mode="rgb_array"``, a bad ``every_n``, ``fps`` or ``fmt``, or a
            ``video_folder`` that cannot be created.
        ImportError: When the ``video`` extra is missing (names it).
    """

    def __init__(
        self,
        env: ParallelEnv,
        video_folder: str | os.PathLike[str],
        episode_trigger: Callable[[int], bool] | None = None,
        *,
        every_n: int = 1,
        name_prefix: str = "rl-video",
        fps: float | None = None,
        fmt: str = "mp4",
    ) -> None:
        mode = getattr(env, "render_mode", None)
        if mode != "rgb_array":
            raise ValueError(
                f"RecordVideo needs an env built with render_mode='rgb_array' (render() must return frames), "
                f"got render_mode={mode!r}"
            )
        if isinstance(every_n, bool) or not isinstance(every_n, int) or every_n < 1:
            raise ValueError(f"every_n must be an integer >= 1, got {every_n!r}")
        if fmt not in VIDEO_FORMATS:
            raise ValueError(f"fmt must be one of {list(VIDEO_FORMATS)}, got {fmt!r}")
        if fps is None:
            fps = (getattr(env, "metadata", None) or {}).get("render_fps") or 30
        if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
            raise ValueError(f"fps must be a number > 0, got {fps!r}")
        check_video_support(fmt)
        folder = Path(video_folder)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"video_folder {str(folder)!r} cannot be created: {exc.strerror or exc}") from None
        super().__init__(env)
        self.video_folder = folder
        self.episode_trigger = episode_trigger if episode_trigger is not None else (lambda k: k % every_n == 0)
        self.name_prefix = name_prefix
        self.fps = float(fps)
        self.fmt = fmt
        self.episode = -1
        self.written: list[Path] = []
        self._writer: VideoWriter | None = None

    @property
    def recording(self) -> bool:
        """Whether the current episode is being filmed."""
        return self._writer is not None

    def video_path(self, episode: int) -> Path:
        """The file of episode ``episode``'s video."""
        return self.video_folder / f"{self.name_prefix}-episode-{episode}.{self.fmt}"

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[Any, Any], dict[Any, dict[str, Any]]]:
        """Reset the env (writing the video of an episode cut short); film the new episode when triggered."""
        self._finish()
        out = self.env.reset(seed=seed, options=options)
        self.episode += 1
        if self.episode_trigger(self.episode):
            self._writer = VideoWriter(self.video_path(self.episode), self.fps)
            self._capture()
        return out

    def step(self, actions: dict[Any, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the env; film the frame; write the video once every agent is done."""
        out = self.env.step(actions)
        if self._writer is not None:
            self._capture()
            if not self.env.agents:
                self._finish()
        return out

    def close(self) -> None:
        """Write the video in progress, if any, and close the env."""
        try:
            self._finish()
        finally:
            self.env.close()

    def _capture(self) -> None:
        assert self._writer is not None
        frame = self.env.render()
        if frame is None:
            raise ValueError("RecordVideo: env.render() returned None; build the env with render_mode='rgb_array'")
        self._writer.append(frame)

    def _finish(self) -> None:
        writer, self._writer = self._writer, None
        if writer is not None:
            path = writer.close()
            if path is not None:
                self.written.append(path)
