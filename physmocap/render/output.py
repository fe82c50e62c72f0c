"""Preview files: MP4 and GIF streamed frame by frame to ``imageio``, PNG contact sheets.

Videos are written frame by frame (memory stays bounded on long clips) to a temporary
file that is renamed over the output only when complete
(:func:`physmocap.fileio.atomic_path`).  Each image carries its frame number (in the
source's numbering) and time.  A contact sheet is a grid of chosen frames: the character
row above the source row.
"""

from __future__ import annotations

import functools
import io
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import OptionError, OutputError
from ..fileio import atomic_path, check_writable, suffix_error, write_error
from ..progress import Progress
from .scene import PreviewScene

__all__ = ["SUFFIXES", "check_output", "check_size", "label", "video_frames", "write_video", "write_sheet", "sheet_frames", "require_imageio"]

SUFFIXES = (".mp4", ".gif", ".png")


def require_imageio():
    """The ``imageio`` module, or a clear error naming the extra to install."""
    try:
        import imageio.v2 as iio
    except ImportError:
        raise OptionError("previews need imageio: pip install 'physmocap[render]'") from None
    return iio


def check_output(path: str | Path) -> Path:
    """The output path if its suffix is known and its folder writable (before any work)."""
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise suffix_error(p, SUFFIXES, "previews")
    check_writable(path)
    return p


def check_size(path: Path, width: int, height: int) -> None:
    """H.264 video (yuv420p) needs an even width and height: say so before any work."""
    if path.suffix.lower() == ".mp4" and (width % 2 or height % 2):
        raise OptionError(f"--size {width}x{height}: an MP4 needs an even width and height", path=path)


@functools.lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)  # Pillow >= 10.1: a scalable font
    except TypeError:  # older Pillow: its small bitmap font
        return ImageFont.load_default()


def label(image: np.ndarray, text: str) -> np.ndarray:
    """The image with ``text`` written in its top-left corner (white on a dark box), the
    font about 1/26 of the image height."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(image)
    draw = ImageDraw.Draw(img)
    font = _font(max(10, image.shape[0] // 26))
    box = draw.textbbox((6, 4), text, font=font)
    draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
    draw.text((6, 4), text, fill=(255, 255, 255), font=font)
    return np.asarray(img)


def _caption(t: int, first: int, fps: float) -> str:
    """``frame N  t=S s``: the time with as many decimals as tell two frames apart."""
    decimals = max(2, int(np.ceil(np.log10(max(float(fps), 1.0)))))
    return f"frame {first + t}  t={(first + t) / fps:.{decimals}f} s"


def video_frames(num_frames: int, clip_fps: float, fps: float | None = None) -> tuple[list[int], float]:
    """Trajectory frames of a video at ``fps`` frames per second (default: the clip's
    rate, at most 30) and that rate: video frame ``n`` shows the clip frame nearest to
    time ``n / fps``."""
    rate = min(float(clip_fps), 30.0) if fps is None else float(fps)
    if not (np.isfinite(rate) and 0.0 < rate <= 240.0):
        raise OptionError(f"--fps must be within (0, 240] frames per second, got {fps}")
    count = int(np.floor((num_frames - 1) / clip_fps * rate + 1e-9)) + 1
    return np.minimum(np.rint(np.arange(count) * clip_fps / rate), num_frames - 1).astype(int).tolist(), rate


def write_video(scene: PreviewScene, frames: Iterable[int], path: Path, fps: float, first: int, progress: bool | None) -> int:
    """Stream the frames to an MP4 or GIF at ``path`` played at ``fps``; returns the number
    written.  Captions give the source frame number (``first`` + trajectory frame) and time."""
    iio = require_imageio()
    frames = list(frames)
    kind = path.suffix.lower()
    n = 0
    with atomic_path(path) as tmp, Progress(len(frames), "preview", enabled=progress) as bar:
        gif = io.BytesIO()  # Pillow holds a GIF's frames until the end: encode in memory, write once
        if kind == ".mp4":
            writer = iio.get_writer(tmp, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=1, ffmpeg_log_level="error")
        else:  # (a write failing in Pillow's close would be retried, and fail again, in its __del__)
            writer = iio.get_writer(gif, format="GIF", mode="I", duration=1000.0 / fps, loop=0)
        try:
            try:
                for t in frames:
                    writer.append_data(label(scene.render(t), _caption(t, first, scene.traj.fps)))
                    n += 1
                    bar.update(1)
            finally:
                writer.close()
        except OSError as exc:
            if exc.errno is not None or kind != ".mp4":
                raise  # a write of this process: atomic_path names the output
            raise _encoder_failure(tmp, path) from None  # imageio's many-line "Broken pipe / FFMPEG COMMAND"
        if kind == ".mp4" and not mp4_complete(tmp):  # ffmpeg died (killed by SIGXFSZ...) after the last frame
            raise _encoder_failure(tmp, path)
        if kind != ".mp4":
            tmp.write_bytes(gif.getvalue())
    return n


def mp4_complete(path: Path) -> bool:
    """True when the MP4 at ``path`` is a whole file: its top-level boxes fill it exactly and
    one is the ``moov`` index ffmpeg writes last (imageio does not check ffmpeg's exit status,
    so a video cut short by a full disk or a file size limit would otherwise pass)."""
    size = path.stat().st_size
    pos, kinds = 0, set()
    with open(path, "rb") as fh:
        while pos < size:
            fh.seek(pos)
            head = fh.read(16)
            if len(head) < 8:
                return False
            box, kind = int.from_bytes(head[:4], "big"), head[4:8]
            if box == 1 and len(head) == 16:
                box = int.from_bytes(head[8:16], "big")
            elif box == 0:
                box = size - pos
            if box < 8 or pos + box > size:
                return False
            kinds.add(kind)
            pos += box
    return b"moov" in kinds


def _encoder_failure(tmp: Path, target: Path) -> OutputError:
    """The error for a video ffmpeg could not finish, naming ``target`` and the likely cause:
    the file size limit (``ulimit -f``), a full disk, or else the encoder itself."""
    import errno
    import os

    size = tmp.stat().st_size if tmp.exists() else 0
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        over_limit = soft != resource.RLIM_INFINITY and size >= soft
    except (ImportError, OSError, ValueError):  # pragma: no cover - not a Unix
        over_limit = False
    if over_limit:
        return write_error(OSError(errno.EFBIG, os.strerror(errno.EFBIG)), target)
    try:
        st = os.statvfs(tmp.parent)
        full = st.f_bavail * st.f_frsize < (1 << 20)
    except (AttributeError, OSError):  # pragma: no cover - not a Unix
        full = False
    if full:
        return write_error(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)), target)
    return OutputError("not written: the video encoder (ffmpeg) stopped before the end of the video", path=target)


def sheet_frames(num_frames: int, count: int = 8, given: Sequence[int] | None = None, first: int = 0) -> list[int]:
    """Trajectory frame indices of a contact sheet: ``given`` source frame numbers, or
    ``count`` evenly spaced ones."""
    if given:
        out = [int(f) - first for f in given]
        bad = [f + first for f in out if not 0 <= f < num_frames]
        if bad:
            raise OptionError(f"--frames: {bad} outside the rendered frames {first}..{first + num_frames - 1}")
        return out
    count = max(1, min(count, num_frames))
    return sorted(set(np.linspace(0, num_frames - 1, count).round().astype(int).tolist()))


#: Most pixels in a contact sheet (about 190 MB of RGB while it is assembled; image viewers
#: and Pillow refuse much larger ones as decompression bombs).
MAX_SHEET_PIXELS = 64_000_000


def sheet_rows(overlay: bool, has_skeleton: bool) -> int:
    """Rows of a contact sheet (:func:`write_sheet`): the character's, and the source's below
    it unless there is no source skeleton or it is drawn over the character."""
    return 1 if overlay or not has_skeleton else 2


def check_sheet(path: Path, frames: int, width: int, height: int, rows: int) -> None:
    """Refuse a contact sheet of ``frames`` columns of ``rows`` panels ``width`` x ``height``
    over :data:`MAX_SHEET_PIXELS`, before any rendering."""
    pixels = frames * rows * width * height
    if pixels > MAX_SHEET_PIXELS:
        panels = f"{frames} frames" + (f" in {rows} rows (character and source)" if rows > 1 else "")
        raise OptionError(
            f"a contact sheet of {panels} at {width}x{height} is {pixels / 1e6:.0f} megapixels, more than "
            f"{MAX_SHEET_PIXELS / 1e6:.0f}: fewer frames (--count, --frames) or a smaller --size; a video (.mp4, .gif) "
            "shows every frame",
            path=path,
        )


def write_sheet(scene: PreviewScene, frames: Sequence[int], path: Path, first: int, progress: bool | None) -> None:
    """A PNG grid: one column per frame, the character row above the source row (with the
    ``overlay`` layout one row, the source skeleton drawn over the character)."""
    iio = require_imageio()
    rows = [[], []]
    overlay = scene.options.layout == "overlay"
    with Progress(len(frames), "preview", enabled=progress) as bar:
        for t in frames:
            rows[0].append(label(scene.render(t, character=True, source=overlay), _caption(t, first, scene.traj.fps)))
            if sheet_rows(overlay, scene.skeleton is not None) == 2:
                rows[1].append(label(scene.render(t, character=False, source=True), "source"))
            bar.update(1)
    grid = np.concatenate([np.concatenate(r, axis=1) for r in rows if r], axis=0)
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, grid, format="PNG")
