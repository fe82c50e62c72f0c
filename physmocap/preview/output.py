"""Write a preview: ``.mp4`` (imageio + imageio-ffmpeg), ``.gif`` (imageio + Pillow)
or ``.png`` (a contact sheet), atomically.

Videos are streamed: each frame goes to the encoder as it is rendered (MP4
memory stays flat for any clip length; a GIF is assembled by Pillow at the
end, so it holds the frames: use MP4 for long clips).  A contact sheet shows
evenly spaced (or chosen) frames in bands of two rows: the character above,
the source skeleton below, seen by the same camera.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from ..errors import OptionError, OutputError
from ..fileio import atomic_open, atomic_path, check_writable
from ..progress import Progress
from .clip import PreviewClip
from .render import ClipRenderer, RenderOptions

__all__ = ["SUFFIXES", "check_preview_path", "sheet_indices", "write_preview"]

#: Output suffix -> what is written.
SUFFIXES = {".mp4": "MP4 video", ".gif": "animated GIF", ".png": "PNG contact sheet"}
#: Default output frame rate cap (frames per second) for videos.
DEFAULT_FPS = 30.0
_INSTALL = "pip install 'physmocap[render]'"


def check_preview_path(path: str | os.PathLike) -> Path:
    """Fail early if ``path`` has an unknown suffix or cannot be written."""
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise OptionError(
            f"cannot write a preview as {p.suffix or 'a file without a suffix'!r}; use one of {sorted(SUFFIXES)}",
            path=p,
        )
    return check_writable(p)


def _imageio():
    try:
        import imageio.v2 as iio2
        import imageio.v3 as iio3
    except ModuleNotFoundError:
        raise OutputError(f"writing previews needs imageio: {_INSTALL}") from None
    return iio2, iio3


def video_indices(clip: PreviewClip, fps: float | None) -> tuple[np.ndarray, float]:
    """Trajectory frames shown at ``fps`` (default: the clip's rate, at most 30) and that rate.

    Frame ``n`` of the video shows the trajectory frame nearest to time ``n / fps``.
    """
    rate = float(clip.trajectory.fps)
    out = min(rate, DEFAULT_FPS) if fps is None else float(fps)
    if not (math.isfinite(out) and 0 < out <= 240):
        raise OptionError(f"--fps must be in (0, 240] frames per second, got {fps}")
    n = max(int(math.floor((clip.num_frames - 1) / rate * out + 1e-9)) + 1, 1)
    return np.minimum(np.rint(np.arange(n) * rate / out).astype(np.int64), clip.num_frames - 1), out


def sheet_indices(clip: PreviewClip, count: int = 8, frames: Sequence[int] | None = None) -> np.ndarray:
    """Trajectory frames for a contact sheet: ``count`` evenly spaced ones, or the
    given source ``frames`` (the numbers written on the images)."""
    if frames:
        index = {int(n): i for i, n in enumerate(clip.frame_numbers)}
        missing = [f for f in frames if int(f) not in index]
        if missing:
            lo, hi = int(clip.frame_numbers[0]), int(clip.frame_numbers[-1])
            raise OptionError(f"--frames {missing} not in the previewed frames {lo} to {hi}")
        return np.array([index[int(f)] for f in frames], dtype=np.int64)
    if not 1 <= count <= 200:
        raise OptionError(f"--count must be between 1 and 200, got {count}")
    return np.unique(np.rint(np.linspace(0, clip.num_frames - 1, min(count, clip.num_frames))).astype(np.int64))


def sheet_image(renderer: ClipRenderer, indices: np.ndarray, bar: Progress) -> np.ndarray:
    """Bands of ``columns`` tiles: character row above source row; 2-pixel gaps."""
    n = len(indices)
    columns = min(n, max(4, math.ceil(math.sqrt(2 * n))))
    rows_per_band = 2 if renderer.clip.skeleton is not None else 1
    h, w = renderer.options.height, renderer.options.width
    gap = 2
    bands = math.ceil(n / columns)
    sheet = np.full((bands * rows_per_band * (h + gap) - gap, columns * (w + gap) - gap, 3), 255, np.uint8)
    for k, i in enumerate(indices):
        y0, x0 = (k // columns) * rows_per_band * (h + gap), (k % columns) * (w + gap)
        sheet[y0 : y0 + h, x0 : x0 + w] = renderer.frame(int(i), skeleton=rows_per_band == 1)
        if rows_per_band == 2:
            y1 = y0 + h + gap
            sheet[y1 : y1 + h, x0 : x0 + w] = renderer.frame(int(i), character=False)
        bar.update(1)
    return sheet


def _frames(renderer: ClipRenderer, indices: np.ndarray, bar: Progress) -> Iterator[np.ndarray]:
    for i in indices:
        yield renderer.frame(int(i))
        bar.update(1)


def write_preview(
    clip: PreviewClip,
    path: str | os.PathLike,
    options: RenderOptions | None = None,
    *,
    fps: float | None = None,
    count: int = 8,
    frames: Sequence[int] | None = None,
    progress: bool | None = None,
) -> Path:
    """Render ``clip`` to ``path`` (``.mp4``, ``.gif`` or ``.png`` sheet); returns the path.

    ``fps`` is the video frame rate; ``count`` / ``frames`` choose the sheet's frames.
    Sheets show the skeleton in its own row, so ``options.overlay`` is ignored there.
    """
    p = check_preview_path(path)
    suffix = p.suffix.lower()
    iio2, iio3 = _imageio()
    options = options or RenderOptions()
    if suffix == ".png":
        indices = sheet_indices(clip, count, frames)
        options = RenderOptions(options.width, options.height, options.camera, True, options.label, options.antialias)
    else:
        if suffix == ".mp4" and (options.width % 2 or options.height % 2):
            raise OptionError(f"MP4 needs an even width and height, got {options.width}x{options.height}")
        indices, fps = video_indices(clip, fps)
    with ClipRenderer(clip, options) as renderer, Progress(len(indices), "preview", enabled=progress) as bar:
        if suffix == ".png":
            image = sheet_image(renderer, indices, bar)
            with atomic_open(p, "wb") as fh:
                iio3.imwrite(fh, image, extension=".png")
            return p
        with atomic_path(p) as tmp:
            if suffix == ".mp4":
                _write_mp4(iio2, tmp, _frames(renderer, indices, bar), fps)
            else:
                with iio3.imopen(tmp, "w", plugin="pillow", extension=".gif") as gif:
                    for image in _frames(renderer, indices, bar):
                        gif.write(image, duration=1000.0 / fps, loop=0)
    return p


def _write_mp4(iio2, path: Path, images: Iterator[np.ndarray], fps: float) -> None:
    """H.264 in yuv420p (plays everywhere), bit-exact flags so equal frames give equal bytes."""
    try:
        writer = iio2.get_writer(
            path,
            format="FFMPEG",
            mode="I",
            fps=fps,
            codec="libx264",
            pixelformat="yuv420p",
            macro_block_size=1,
            ffmpeg_log_level="error",
            output_params=["-fflags", "+bitexact", "-flags:v", "+bitexact", "-threads", "1"],
        )
    except (ImportError, RuntimeError) as exc:
        raise OutputError(f"cannot start the MP4 encoder ({exc}); {_INSTALL} (imageio-ffmpeg)") from None
    try:  # not ``with writer``: imageio's writers skip close() when an exception is raised
        for image in images:
            writer.append_data(image)
    finally:
        writer.close()  # waits for ffmpeg, so the file is complete (or removable) afterwards
