"""The cleaner's thresholds and repair settings (:class:`CleanOptions`), each a physical
quantity with its unit, and the documentation the ``physmocap clean`` flags are generated
from (:func:`option_docs`)."""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass, field, fields

from ..errors import OptionError

__all__ = ["CleanOptions", "UNITS", "option_docs", "option_unit"]

#: The units an option may carry, and how a reader says them.
UNITS = {
    "deg": "degrees",
    "deg/s": "degrees per second",
    "m": "metres",
    "m/s": "metres per second",
    "s": "seconds",
    "ratio": "a dimensionless ratio",
    "count": "a whole number",
}


def _opt(default: float, unit: str):
    """A :class:`CleanOptions` field with its ``unit`` (a key of :data:`UNITS`)."""
    assert unit in UNITS, unit
    return field(default=default, metadata={"unit": unit})


@dataclass(frozen=True)
class CleanOptions:
    """Detection thresholds and repair settings.

    Attributes:
        jump_deg: Smallest frame-to-frame rotation (degrees) that can be a glitch.
        max_speed: A single jump (not undone later) is a glitch only if faster than this
            (degrees per second): joints of the fastest human motions (throws, kicks) stay
            below about 1500 deg/s outside the shoulder's internal rotation, so at a low
            frame rate a large step is no glitch.
        pair_speed: A jump paired with a later jump that undoes it needs only this speed
            (degrees per second, both jumps): going out and coming back is stronger evidence
            than one step, but a joint stepping no faster than a walking knee (about 400
            deg/s) cannot be told from real motion sampled at a low rate.
        novelty_ratio: A spike (not a flip) is a glitch only if the poses it holds lie at
            least this fraction of its entry jump away from every pose the joint takes
            elsewhere in the clip (outside the span and as many frames each side): a joint
            popping out and back to a pose it reaches anyway (a toe flexing at each landing, a
            solved spine settling) is the capture's own behaviour, an offset injected or added
            by a solver error puts the joint where it never goes.  Not asked of a pair whose
            two jumps are each impossible on their own (faster than ``max_speed`` and moving the
            limb ``jump_distance``): out and back that way is a glitch wherever it goes.
        jump_ratio: A jump is at least this many times the median step of its neighbours
            (``context_time`` each side): real fast motion moves on every frame, a glitch in one.
        context_time: Seconds of neighbours (each side) for the median step a jump is
            compared with.
        max_glitch_time: Longest glitch between a jump and its return (seconds); longer
            out-of-range spans are reported, not changed.
        return_ratio: The return brings the joint back to within this fraction of the jump.
        return_deg: The exit leaves at most this many degrees of the entry undone, on top of
            twice the joint's own motion on the two frames (its median step over
            ``context_time`` before or after each jump, whichever is larger: a toe at 30 Hz
            still swinging into the frame a glitch starts on).
        flip_deg: A glitch whose jump is at least this large (degrees) is a flip.
        frozen_time: Shortest frozen run (seconds).
        stretch_ratio: Bone-length departure from the median that is a glitch (a fraction of
            the median; positional sources), if also beyond ``stretch_distance``.
        stretch_distance: ... and beyond this many metres: a joint centre read off skin
            markers carries their soft-tissue artefact, up to 2-3 cm on the thigh (Leardini
            et al. 2005, Gait & Posture 21:212), so a short bone (a hand, a toe) varies by
            more than its ``stretch_ratio`` without any glitch.
        rom_soft_margin: Degrees added, for the anatomical check, to each range of motion
            that performers exceed (the ``"default"`` ranges of :mod:`physmocap.models.rom`
            already carry a 15 degree margin over the largest clinical value; dancers'
            hips and trunks go further).  Anatomical stops (knee and elbow
            hyperextension) get none.
        swap_min_distance: A left joint and its right twin are traded where relabelling them
            brings the two (summed) this many metres nearer to where their motion was heading
            than the labels do, over the trade (positional sources): traded, each is off by
            the pair's distance, so pairs closer than about half this cannot be told apart
            (they also matter least).
        jump_distance: A single jump (a discontinuity) must also move some point of the
            joint's limb (its descendants, relative to the joint) this many metres farther
            than the limb moves on the neighbouring frames: a toe, finger or twist popping by
            a couple of centimetres is within a solved skeleton's soft-tissue noise (skin
            markers slide 1-3 cm on the bone).  An offset, so independent of the frame rate.
        carry_ratio: A spike's jumps must turn the joint's segment and what it carries:
            its world orientation jumps by at least this fraction of its local jump, and
            some child's world orientation by at least this fraction of its own (an offset
            on one joint turns everything it carries by the same angle).  A solver moving a
            bend between consecutive joints turns one while the next turns back, and the
            limbs beyond stay where they were.
        still_speed: A joint turning slower than this (degrees per second) is not moving (a
            capture's noise floor): the body moves on a frame where its median joint turns
            faster, and a frozen joint's catch-up is compared with at least this speed.
            Per second, so the same at every frame rate (0.05 degrees per frame at 120 Hz).
        still_velocity: A joint moving slower than this (metres per second) is not moving,
            on joint-position sources: quiet standing sways at about 1 cm/s (mean
            centre-of-pressure velocity, Prieto et al. 1996, IEEE Trans. Biomed. Eng.
            43:956); the body moves on a frame where its median joint is faster.
        offset_min_time: A spike or flip lasting this many seconds or more is repaired by
            taking its offset off (entry jump and inverse exit jump, interpolated over the
            span: the real motion under it comes back); a shorter one is bridged.
        match_context: The matched bridge's template spans this many times the glitch's
            length of frames on each side of it (at least 2 frames).
        match_own_weight: Weight of the glitched joint's own rotations on those context
            frames in the template (its motion into and out of the span says most about it).
        match_windows: How many best-matching windows of the clip lend their motion
            (averaged) to the matched bridge (and as many windows of the body mirrored left
            to right to the mirrored one).
        blend_ratio: The bridges (cubic, matched, mirrored, regressed) whose error at rebuilding the
            joint's own motion next to the span is within this many times the best one's
            (summed squared degrees) are averaged, weighted by the inverse of that error; 1
            keeps the best alone where it is strictly best.
        regress_ridge: Ridge penalty of the regressed bridges (a bridged joint's pose and its
            steps regressed on the other joints' rotations and their velocities, fitted on the
            clip's good frames, and its departure from its cubic bridge regressed on the other
            joints' departures from theirs, :mod:`physmocap.clean.regress`), per training frame, on
            features standardised to unit variance: small enough to follow the body (0.001 and
            0.1 remove about as much of the benchmark's frozen joints' error), large enough
            to keep hundreds of correlated channels from fitting noise.
        contact_speed: A point below a bridged joint (its lowest, a toe or a heel) stands on
            the floor on a good frame next to the span where it moves slower than this
            (metres per second) ...
        contact_height: ... within this many metres of the clip's floor (the lowest joint,
            a low percentile over the frames).
        contact_radius: The stance goes on into the bridged span while the bridge keeps the
            point within this many metres of where it stood ...
        contact_lever: ... and within this fraction of its distance from the bridged joint
            (a foot's toe, 15 cm from the ankle, is held to 4 cm) ...
        contact_reach: ... and the limb below the joint, its rotations all good, can still
            reach it: its distance from the joint within this many metres of the limb's own.
        contact_ramp: The turn that keeps the point standing eases out over this many
            seconds after the stance.
        plane_min_deg: A lost or held joint position rides on the plane of its parent, its
            child and its parent's parent (positional sources) only where the two bones
            from the parent make at least this many degrees with a straight line on every
            frame: nearer a line the plane's normal follows each millimetre of noise (an
            ankle between a straight knee and the toe).
    """

    jump_deg: float = _opt(10.0, "deg")
    max_speed: float = _opt(1500.0, "deg/s")
    pair_speed: float = _opt(400.0, "deg/s")
    novelty_ratio: float = _opt(0.2, "ratio")
    jump_ratio: float = _opt(5.0, "ratio")
    context_time: float = _opt(0.1, "s")
    max_glitch_time: float = _opt(0.5, "s")
    return_ratio: float = _opt(0.5, "ratio")
    return_deg: float = _opt(2.0, "deg")
    flip_deg: float = _opt(150.0, "deg")
    frozen_time: float = _opt(0.1, "s")
    stretch_ratio: float = _opt(0.1, "ratio")
    stretch_distance: float = _opt(0.03, "m")
    rom_soft_margin: float = _opt(15.0, "deg")
    swap_min_distance: float = _opt(0.05, "m")
    jump_distance: float = _opt(0.05, "m")
    carry_ratio: float = _opt(0.5, "ratio")
    still_speed: float = _opt(6.0, "deg/s")
    still_velocity: float = _opt(0.01, "m/s")
    offset_min_time: float = _opt(0.15, "s")
    match_context: float = _opt(0.5, "ratio")
    match_own_weight: float = _opt(5.0, "ratio")
    match_windows: int = _opt(3, "count")
    blend_ratio: float = _opt(3.0, "ratio")
    regress_ridge: float = _opt(0.01, "ratio")
    contact_speed: float = _opt(0.2, "m/s")
    contact_height: float = _opt(0.1, "m")
    contact_radius: float = _opt(0.1, "m")
    contact_lever: float = _opt(0.25, "ratio")
    contact_reach: float = _opt(0.02, "m")
    contact_ramp: float = _opt(0.1, "s")
    plane_min_deg: float = _opt(30.0, "deg")

    def __post_init__(self) -> None:
        from ..options import check_fields

        check_fields(
            self,
            "clean",
            counts=[f.name for f in fields(self) if option_unit(f.name) == "count"],
            positive=[f.name for f in fields(self) if f.name != "rom_soft_margin"],
        )
        if not self.plane_min_deg < 90.0:
            raise OptionError(f"clean option plane_min_deg must be in (0, 90) degrees, got {self.plane_min_deg!r}")
        if not self.blend_ratio >= 1.0:
            raise OptionError(f"clean option blend_ratio must be at least 1 (the best estimate's error times it), "
                              f"got {self.blend_ratio!r}")
        if not MIN_RIDGE <= self.regress_ridge <= MAX_RIDGE:
            # the fit's matrix is only as well conditioned as the ridge makes it (constant and
            # duplicated channels); a ridge so large it overflows fits nothing
            raise OptionError(f"clean option regress_ridge must be in [{MIN_RIDGE:g}, {MAX_RIDGE:g}], "
                              f"got {self.regress_ridge!r}")


#: Bounds of ``CleanOptions.regress_ridge`` (per training frame, on standardised features).
MIN_RIDGE = 1e-8
MAX_RIDGE = 1e4


def option_unit(name: str) -> str:
    """The unit (a key of :data:`UNITS`) of the :class:`CleanOptions` field ``name``."""
    return next(f.metadata["unit"] for f in fields(CleanOptions) if f.name == name)


def option_docs() -> dict[str, str]:
    """Field name -> its documentation in :class:`CleanOptions`' ``Attributes`` section, as
    plain text (reST markup dropped, lines joined): the one description the docs and the
    command-line help share."""
    doc = inspect.cleandoc(CleanOptions.__doc__ or "")
    section = doc.split("Attributes:", 1)[1]
    out: dict[str, str] = {}
    name = None
    for line in section.splitlines():
        m = re.match(r"^    (\w+): (.*)$", line)
        if m:
            name = m.group(1)
            out[name] = m.group(2).strip()
        elif name and line.strip():
            out[name] += " " + line.strip()
    for k, v in out.items():
        v = re.sub(r":\w+:`~?([^`]+)`", r"\1", v)  # :mod:`x` -> x
        out[k] = v.replace("``", "")
    return out
