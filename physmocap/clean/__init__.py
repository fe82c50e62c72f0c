"""Glitch detection and repair in the source's own skeleton (``physmocap clean``).

* :mod:`.detect`: spikes, flips, discontinuities, frozen joints, and anatomical glitches
  (:mod:`.anatomy`: a joint beyond its range of motion, named by anatomical movement);
  :mod:`.positional`: bone stretch, gaps, frozen joints and left/right swaps of
  joint-position sources.
* :mod:`.options`: the thresholds (:class:`CleanOptions`), physical quantities with units.
* :mod:`.correct`: interpolation over the repairable ones, nothing else touched;
  :mod:`.resolve`: those whose interpolated pose leaves a range of motion re-solved through the
  hard-limited IK on an actor-fitted humanoid.

``clean(motion) -> (Motion, GlitchReport)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..resources import display_path
from .options import CleanOptions

if TYPE_CHECKING:  # the detectors load scipy: imported when used (``physmocap --help`` stays fast)
    from ..motion import Motion
    from .correct import correct_glitches
    from .detect import Glitch, detect_glitches

__all__ = ["CleanOptions", "Glitch", "GlitchReport", "clean", "detect_glitches", "correct_glitches"]


def __getattr__(name: str):
    if name in ("Glitch", "detect_glitches"):
        from . import detect

        return getattr(detect, name)
    if name == "correct_glitches":
        from .correct import correct_glitches

        return correct_glitches
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class GlitchReport:
    """What :func:`clean` found and did."""

    source: str
    frames: int
    fps: float
    glitches: tuple[Glitch, ...]

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "frames": self.frames,
            "fps": self.fps,
            "glitches": [g.as_dict() for g in self.glitches],
        }

    def table(self) -> str:
        """A readable table: type, joint, anatomical movement, frames, severity, correction."""
        if not self.glitches:
            return f"{self.source}: no glitch found in {self.frames} frames\n"
        rows = [f"{'type':14s} {'joint':22s} {'movement':34s} {'frames':>13s} {'severity':>10s}  corrected"]
        for g in self.glitches:
            frames = f"{g.start}" if g.start == g.end else f"{g.start}-{g.end}"
            movement = f"{g.movement} ({g.plane})" if g.movement else f"with {g.other}" if g.other else "-"
            digits = {"m": 3, "s": 2}.get(g.unit, 1)  # millimetres, hundredths of a second, tenths of a degree
            rows.append(
                f"{g.kind:14s} {g.joint:22s} {movement:34s} {frames:>13s} {g.severity:7.{digits}f} {g.unit:3s}  "
                f"{g.corrected or 'reported only'}"
            )
        return "\n".join(rows) + "\n"


def _check_finite(motion: Motion) -> None:
    """Refuse a motion with a non-finite rotation, translation or (confident) position,
    naming the first joint and frame: no detector can read it and no output can hold it.

    Raises:
        InputError: ``"<source>: frame <f>: joint '<name>' has a non-finite <what>"``.
    """
    import numpy as np

    from ..errors import InputError

    arrays = {"rotation": motion.rotations, "translation": motion.translations, "position": motion.positions}
    for what, arr in arrays.items():
        if arr is None:
            continue
        a = np.asarray(arr)
        bad = ~np.isfinite(a).all(axis=-1)
        if what == "position" and motion.confidence is not None:
            bad &= np.asarray(motion.confidence) > 0.0  # a lost marker's position is not read
        if bad.any():
            f, k = (int(i[0]) for i in np.nonzero(bad))
            j = int(motion.translated[k]) if what == "translation" else k
            raise InputError(
                f"joint {motion.skeleton.names[j]!r} has a non-finite {what}; nothing cleaned",
                path=motion.source,
                frame=f,
            )


def clean(
    motion: Motion, options: CleanOptions | None = None, mapping=None, resolve: str = "limits"
) -> tuple[Motion, GlitchReport]:
    """Detect the glitches of ``motion`` and repair those that can be (:mod:`.correct`);
    ``mapping``: a source mapping file or dict naming its joints (``--source-map``);
    ``resolve``: where repairs are re-solved through the hard-limited IK (:mod:`.resolve`:
    "limits", where the interpolation leaves a range of motion; "never"; "always").

    Raises:
        InputError: A rotation, translation or position is not finite (the file's reader
            refuses those; a motion built in Python may hold them).
    """
    from .correct import correct_glitches
    from .detect import detect_glitches

    _check_finite(motion)
    found = detect_glitches(motion, options, mapping)
    fixed, done = correct_glitches(motion, found, options, resolve=resolve, mapping=mapping)
    return fixed, GlitchReport(display_path(motion.source), motion.num_frames, float(motion.fps), tuple(done))
