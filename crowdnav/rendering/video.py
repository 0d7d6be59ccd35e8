"""Write frames to MP4 (ffmpeg from the imageio-ffmpeg wheel: no system ffmpeg needed) or GIF."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.files import temporary_beside

if TYPE_CHECKING:
    from imageio.core.format import Format

VIDEO_FORMATS = (".mp4", ".gif")


class VideoWriter:
    """Streams ``uint8`` (H, W, 3) frames to ``path``; the suffix picks the format.

    MP4 frames go straight to the encoder; GIF frames are kept until :meth:`close` (Pillow
    writes GIFs in one go). Use as a context manager.
    """

    def __init__(self, path: str | Path, fps: float = 10.0):
        self.path = Path(path)
        self.fps = float(fps)
        suffix = self.path.suffix.lower()
        if suffix not in VIDEO_FORMATS:
            raise ValueError(f"unsupported video format {suffix!r} for {self.path}; expected one of {', '.join(VIDEO_FORMATS)}")
        # written under a temporary name, renamed over ``path`` when whole: a link at ``path`` is replaced, never written through
        self._temporary = temporary_beside(self.path, suffix)
        self._gif_frames: list[np.ndarray] | None = [] if suffix == ".gif" else None
        self._mp4: Format.Writer | None = None
        self.frames_written = 0

    def append(self, frame: np.ndarray) -> None:
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"expected a uint8 frame of shape (H, W, 3), got {frame.dtype} {frame.shape}")
        if self._gif_frames is not None:
            self._gif_frames.append(frame)
        else:
            if self._mp4 is None:
                import imageio.v2 as imageio  # imported lazily: only video writing needs it

                # macro_block_size=1: the renderer already makes sides multiples of 16, never resize.
                self._mp4 = imageio.get_writer(
                    self._temporary, fps=self.fps, codec="libx264", quality=7, macro_block_size=1, ffmpeg_params=["-preset", "veryfast"]
                )
            self._mp4.append_data(frame)
        self.frames_written += 1

    def close(self) -> Path:
        if self._gif_frames is not None:
            if not self._gif_frames:
                raise ValueError(f"no frames to write to {self.path}")
            import imageio.v3 as iio

            iio.imwrite(self._temporary, np.stack(self._gif_frames), duration=1000.0 / self.fps, loop=0)
            self._gif_frames = []
        elif self._mp4 is not None:
            self._mp4.close()
            self._mp4 = None
        if self._temporary.exists():  # not on a second close
            os.replace(self._temporary, self.path)
        return self.path

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        if kind is None:
            self.close()
            return
        if self._mp4 is not None:  # an episode that raised: its unfinished video is dropped
            self._mp4.close()
            self._mp4 = None
        self._temporary.unlink(missing_ok=True)


def write_video(frames: Iterable[np.ndarray], path: str | Path, fps: float = 10.0) -> Path:
    """Write an iterable of frames to ``path`` (MP4 or GIF) and return the path."""
    with VideoWriter(path, fps) as writer:
        for frame in frames:
            writer.append(frame)
    return writer.path
