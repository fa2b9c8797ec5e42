"""Writing RGB frames to GIF and MP4 files (the only importer of Pillow and imageio in the package).

Both formats need the optional ``video`` extra (``pip install "agentsim-env[video]"``: imageio, imageio-ffmpeg,
whose wheel ships an ffmpeg binary, and Pillow); nothing is imported before the first video is written, and a
missing package raises an ``ImportError`` naming the extra. GIFs are written with Pillow (imageio when Pillow is
missing), MP4s (H.264, yuv420p) with imageio-ffmpeg.

:class:`VideoWriter` takes frames one at a time (an MP4 is streamed to ffmpeg as they come, a GIF keeps each
frame as 8-bit palette image until it is closed); :func:`write_video` writes an iterable of frames in one call.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

__all__ = ["VIDEO_FORMATS", "VideoWriter", "check_video_support", "png_rgb", "video_format", "write_video"]

#: File suffixes a video can be written as.
VIDEO_FORMATS: tuple[str, ...] = ("mp4", "gif")
_EXTRA = 'pip install "agentsim-env[video]"'


def video_format(path: str | os.PathLike[str]) -> str | None:
    """``"mp4"`` or ``"gif"`` by the suffix of ``path`` (any case), else None."""
    suffix = Path(path).suffix.lower().lstrip(".")
    return suffix if suffix in VIDEO_FORMATS else None


def _missing(fmt: str, what: str, exc: ImportError) -> ImportError:
    return ImportError(f"writing {fmt.upper()} video needs {what}: {_EXTRA} ({exc})")


def check_video_support(fmt: str) -> None:
    """Raise now, rather than after a rollout, when the packages that write ``fmt`` are missing.

    Raises:
        ValueError: For a format other than ``"mp4"`` and ``"gif"``.
        ImportError: Naming the ``video`` extra, when a needed package is not installed.
    """
    if fmt not in VIDEO_FORMATS:
        raise ValueError(f"video format must be one of {list(VIDEO_FORMATS)}, got {fmt!r}")
    if fmt == "gif":
        _gif_backend()
    else:
        _imageio_ffmpeg()


def _gif_backend() -> str:
    """``"pillow"`` or ``"imageio"``: what writes GIFs here."""
    try:
        import PIL.Image  # noqa: F401
    except ImportError as exc:
        try:
            import imageio.v2  # noqa: F401
        except ImportError:
            raise _missing("gif", "Pillow or imageio", exc) from None
        return "imageio"
    return "pillow"


def _imageio_ffmpeg() -> Any:
    """The ``imageio.v2`` module, after checking that imageio-ffmpeg (and its ffmpeg binary) is there."""
    try:
        import imageio.v2 as iio
        import imageio_ffmpeg
    except ImportError as exc:
        raise _missing("mp4", "imageio and imageio-ffmpeg", exc) from None
    try:
        imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:  # the wheel's binary is missing or not runnable here
        raise ImportError(f"writing MP4 video needs an ffmpeg binary: {_EXTRA} ({exc})") from None
    return iio


def _even(frame: np.ndarray) -> np.ndarray:
    """The frame padded (edge pixels repeated) to an even width and height, as H.264 in yuv420p needs."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _as_rgb(frame: Any) -> np.ndarray:
    """``frame`` as a contiguous ``(H, W, 3)`` uint8 array (checked)."""
    a = np.asarray(frame)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.dtype != np.uint8:
        raise ValueError(f"a video frame must be an (H, W, 3) uint8 array, got shape {a.shape} dtype {a.dtype}")
    return np.ascontiguousarray(a[..., :3])


class VideoWriter:
    """A GIF or MP4 file written frame by frame (the format follows the suffix of ``path``).

    Every frame must have the size of the first. Use as a context manager, or call :meth:`close`: the file is
    complete only then (a writer closed without frames writes nothing; one left by an exception is removed).

    Args:
        path: ``*.mp4`` or ``*.gif`` (its folder must exist).
        fps: Frames per second, > 0.

    Raises:
        ValueError: For another suffix or a bad ``fps``.
        ImportError: When the ``video`` extra is missing (names it).
    """

    def __init__(self, path: str | os.PathLike[str], fps: float) -> None:
        fmt = video_format(path)
        if fmt is None:
            raise ValueError(f"{str(path)!r}: a video file must end in .mp4 or .gif")
        if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
            raise ValueError(f"fps must be a number > 0, got {fps!r}")
        check_video_support(fmt)
        self.path = Path(path)
        self.fmt = fmt
        self.fps = float(fps)
        self.frames = 0
        self._shape: tuple[int, ...] | None = None
        self._gif: list[Any] = []
        self._mp4: Any = None
        self._backend = _gif_backend() if fmt == "gif" else "imageio-ffmpeg"

    def append(self, frame: np.ndarray) -> None:
        """Add one ``(H, W, 3)`` uint8 frame."""
        a = _as_rgb(frame)
        if self._shape is None:
            self._shape = a.shape
        elif a.shape != self._shape:
            raise ValueError(f"every video frame must have the first one's shape {self._shape}, got {a.shape}")
        if self.fmt == "gif":
            self._gif.append(self._palette(a))
        else:
            if self._mp4 is None:
                iio = _imageio_ffmpeg()
                self._mp4 = iio.get_writer(
                    str(self.path),
                    format="FFMPEG",
                    mode="I",
                    fps=self.fps,  # type: ignore[call-overload]
                    codec="libx264",
                    pixelformat="yuv420p",
                    macro_block_size=1,
                    ffmpeg_log_level="error",
                )
            self._mp4.append_data(_even(a))
        self.frames += 1

    def _palette(self, a: np.ndarray) -> Any:
        """A GIF frame as kept until closing: an 8-bit palette PIL image (Pillow) or the array (imageio)."""
        if self._backend == "imageio":
            return a
        from PIL import Image

        return Image.fromarray(a).quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)

    def close(self) -> Path | None:
        """Finish the file; returns its path (None when no frame was given)."""
        if self._mp4 is not None:
            self._mp4.close()
            self._mp4 = None
            return self.path
        if not self._gif:
            return None
        frames, self._gif = self._gif, []
        duration = 1000.0 / self.fps  # milliseconds per frame (GIF stores hundredths of a second)
        if self._backend == "pillow":
            frames[0].save(
                self.path,
                save_all=True,
                append_images=frames[1:],
                duration=duration,
                loop=0,
                optimize=False,
                disposal=1,
            )
        else:  # pragma: no cover - only without Pillow
            import imageio.v2 as iio

            iio.mimsave(str(self.path), frames, format="GIF", duration=duration, loop=0)  # type: ignore[call-overload]
        return self.path

    def abort(self) -> None:
        """Drop the frames given so far and remove a partly written file."""
        self._gif = []
        if self._mp4 is not None:
            try:
                self._mp4.close()
            finally:
                self._mp4 = None
                self.path.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def write_video(frames: Iterable[np.ndarray], path: str | os.PathLike[str], fps: float) -> Path:
    """Write ``frames`` (``(H, W, 3)`` uint8, one size) to ``path`` (``.mp4`` or ``.gif``).

    Frames are consumed one at a time, so a generator of frames is never held in memory as RGB arrays.

    Args:
        frames: The frames, in order (at least one).
        path: The video file; ``.mp4`` (H.264) or ``.gif`` by its suffix. Its folder must exist.
        fps: Frames per second, > 0.

    Returns:
        The path written.

    Raises:
        ValueError: For another suffix, a bad ``fps``, no frames or frames of mixed sizes.
        ImportError: When the ``video`` extra is missing (``pip install "agentsim-env[video]"``).
    """
    writer = VideoWriter(path, fps)
    try:
        for frame in frames:
            writer.append(frame)
    except BaseException:
        writer.abort()
        raise
    out = writer.close()
    if out is None:
        raise ValueError(f"{str(path)!r}: no frames to write")
    return out


def png_rgb(data: bytes) -> np.ndarray:
    """A PNG image (the bytes of a file, such as a browser's screenshot) as an ``(H, W, 3)`` uint8 array.

    Raises:
        ImportError: When Pillow is missing (names the ``video`` extra).
    """
    import io

    try:
        from PIL import Image
    except ImportError as exc:
        raise ImportError(f"reading PNG frames needs Pillow: {_EXTRA} ({exc})") from None
    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGB"))
