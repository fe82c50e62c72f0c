r"""Turning a planted foot towards its target heading (offline and streaming planting).

Two held contact points fix a foot's heading.  Held where it landed, a foot keeps
whatever heading error its swing ended with, and it keeps it while the actor pivots
on it: the hip winds up to reach the foot, and when one point lets go the foot
swings round the other in a few frames (the CMU dance: a left foot held 13 degrees
from its target through a 1.2 s stance, then its heel swivelling 10 cm on the floor
in 5 frames as it lifted).

:class:`HeadingFollower` measures, per foot held at two or more points, the yaw
:math:`e` of its holds against its *aim* (below), and turns the holds by

.. math::

    \tau = \operatorname{clip}\bigl(-(e - \operatorname{clip}(e, -f, f)),\;
            \min(0, \Delta\psi) - \omega/F,\; \max(0, \Delta\psi) + \omega/F\bigr)

where :math:`f` is the dead band (``PlantOptions.pivot_threshold``: a capture's
drift of a degree or two does not swivel the foot), :math:`\Delta\psi` the aim's
own signed change since the previous frame (a pivot on a planted foot is followed at once,
however fast, in its own direction; so is the aim's knee part, below, wobble included: low-passed or only
followed at the rate, it left the foot off its free pose when a point let go, and the
dance's foot slip rose again, 0.98 -> 1.14 cm/s) and :math:`\omega` the rate (rad/s,
``PlantOptions.heading_rate``) at which an error already there when the foot was
caught (a landing off the target's heading) is taken out, :math:`F` the frame rate.  (The
bound was once :math:`\pm(|\Delta\psi| + \omega/F)`: an aim wobbling by a degree either way
about a fixed heading then took a landing's error out twice as fast, the foot swivelling on
the floor.)

Headings (radians, about world Z):

- *target*: where the ankle has an orientation target, the rest-pose vector from the
  foot's first to its last contact site, carried by the ankle's rotation from its
  rest orientation to its target orientation; otherwise the heading of the ankle-to-toe
  target positions plus that vector's rest-pose heading against the ankle-to-toe one;
- *held*: the heading from the first to the last held point's anchor, less that
  pair's rest-pose heading against the reference vector's, so every pair of held
  points reads the same foot heading (the feet stand flat in the rest pose);
- *aim* (:meth:`HeadingFollower.reference`): the target heading, moved where the knees
  are bent towards the heading that points the character's knee where the actor's
  points.  A character's ankle has no axial turn (neither the humanoid's nor a
  robot's), so a held foot's heading decides where its bent knee points; an actor's
  knee and foot can differ by 20 degrees and more in a crouch (real knees turn about
  the shank when bent).  Held on the actor's foot heading, the CMU dance's crouched
  stances put the humanoid's shank 10 degrees off the actor's; held on the knee's,
  its feet 19 degrees off the actor's (median over flat stances).  The aim goes
  :data:`LEG_SHARE` (half) of the way, as the knees bend from :data:`BEND_FROM` to
  :data:`BEND_FULL` (a walk's stance knee reaches the band at times: on the CMU walk the
  aim is up to 5 degrees off the target heading).

A target pitched more than :data:`~physmocap.ik.planting.HEADING_PITCH` (its
reference vector's horizontal part shorter than :math:`\cos` of it) gives no heading:
the foot is not turned on that frame.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..rotations import cross, quat_apply, quat_conj, quat_mul
from .easing import smoothstep


def wrap_angle(a: float) -> float:
    """``a`` wrapped into :math:`[-\\pi, \\pi)` (radians)."""
    return float((a + np.pi) % (2.0 * np.pi) - np.pi)


def _heading(v: np.ndarray) -> float:
    return float(np.arctan2(v[1], v[0]))


def knee_plane(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray) -> tuple[float, float]:
    r"""Where a leg's knee points and how bent it is.

    With the knee axis :math:`n = \widehat{(k - h) \times (a - k)}`, the horizontal direction
    in the leg's plane, :math:`n \times \hat z`, is the way a bent knee points; returns its
    heading :math:`\operatorname{atan2}(-n_x, n_y)` and the angle between thigh and shank
    (radians; 0 for a straight leg, or a leg whose plane is nearly horizontal, which has
    no such direction)."""
    thigh, shank = knee - hip, ankle - knee
    n = cross(thigh, shank)
    norm = float(np.linalg.norm(n))
    if norm < 1e-12:
        return 0.0, 0.0
    n = n / norm
    if np.hypot(n[0], n[1]) < 0.5:
        return 0.0, 0.0
    return float(np.arctan2(-n[0], n[1])), float(np.arctan2(norm, float(np.dot(thigh, shank))))


#: Radians: knees bent less than this (actor's or character's) hold the foot at its own
#: target heading; bent more than :data:`BEND_FULL`, :data:`LEG_SHARE` of the way to the
#: heading that points the character's knee where the actor's points.
BEND_FROM = np.radians(20.0)
BEND_FULL = np.radians(40.0)
LEG_SHARE = 0.5
#: Radians: a knee plane further than this from the foot's target heading is a knee that
#: bends the other way from the actor's (a reverse-knee robot): it gives no aim (without the
#: bound, such a knee's wobble of a millimetre flipped the aim between +-67 degrees).
MAX_KNEE_TURN = np.radians(60.0)


class _Foot:
    """One foot's rest geometry: its contact sites (indices into the planter's sites),
    their rest positions, the reference vector (first to last site, world, rest pose),
    the ankle's and toe's target indices and the ankle's rest orientation."""

    def __init__(self, ankle: int, toe: int, sites: np.ndarray, rest_sites: np.ndarray,
                 ankle_rest: np.ndarray, rest_ankle_toe: np.ndarray | None) -> None:
        self.sites = sites
        #: site index -> its position in ``sites``
        self.order = {int(k): i for i, k in enumerate(sites)}
        self.rest_sites = rest_sites
        self.reference = rest_sites[-1] - rest_sites[0]
        self.ankle = ankle
        self.toe = toe
        #: x-y-z-w rest orientation of the ankle's frame
        self.ankle_rest = ankle_rest
        self._ankle_rest_inverse = quat_conj(ankle_rest)
        #: rest heading of the reference vector against the ankle-to-toe vector's (None: no toe)
        self.toe_offset = None if rest_ankle_toe is None else wrap_angle(
            _heading(self.reference) - _heading(rest_ankle_toe))


class HeadingFollower:
    """Per frame, how far to turn the holds of each foot (see the module docstring).

    Args:
        has_orientation: ``(N,)`` which targets have an orientation.
        feet: ``side -> (ankle target index, toe target index, contact site indices
            heel to toe, (n, 3) their rest positions, (4,) x-y-z-w rest orientation of
            the ankle's frame, (3,) rest ankle-to-toe vector or None)``.
        fps: Frame rate.
        free: Dead band (radians).
        rate: Correction rate (radians per second).
        max_pitch: Radians; a target pitched more than this gives no heading.
        legs: Side -> target indices of its hip, knee and ankle (:meth:`reference`).
    """

    def __init__(self, has_orientation: Sequence[bool], feet: dict, fps: float, free: float, rate: float,
                 max_pitch: float, legs: dict[str, tuple[int, int, int]] | None = None) -> None:
        self.has_orientation = np.asarray(has_orientation, dtype=bool)
        #: side -> target indices of hip, knee and ankle
        self.legs = dict(legs or {})
        self._leg_rows = {side: np.array(leg, dtype=int) for side, leg in self.legs.items()}
        self.feet = {side: _Foot(*spec) for side, spec in feet.items()}
        self.free = float(free)
        self.step_rate = float(rate) / float(fps)
        self.min_level = float(np.cos(max_pitch))
        self._previous: dict[str, float] = {}

    def target_heading(self, side: str, positions: np.ndarray, orientations: np.ndarray | None,
                       valid: np.ndarray | None) -> float | None:
        """The foot's target heading (radians), None where it has none on this frame."""
        foot = self.feet[side]
        ok = valid is None or bool(valid[foot.ankle])
        if ok and orientations is not None and self.has_orientation[foot.ankle]:
            q = np.asarray(orientations[foot.ankle], dtype=float)
            q = quat_mul(q / np.linalg.norm(q), foot._ankle_rest_inverse)
            v = quat_apply(q, foot.reference)
            offset = 0.0
        elif ok and foot.toe_offset is not None and (valid is None or bool(valid[foot.toe])):
            v = positions[foot.toe] - positions[foot.ankle]
            offset = foot.toe_offset
        else:
            return None
        if np.hypot(v[0], v[1]) <= self.min_level * np.linalg.norm(v):  # too steep, or no length
            return None
        return wrap_angle(_heading(v) + offset)

    def held_heading(self, side: str, held: np.ndarray, anchors: np.ndarray) -> float:
        """The heading (radians) the holds ``held`` (site indices, heel to toe, two or more)
        give the foot, from their anchors ``(n, 3)`` of every site."""
        foot = self.feet[side]
        i, j = int(held[0]), int(held[-1])
        a = anchors[j] - anchors[i]
        ri, rj = foot.order[i], foot.order[j]
        pair = foot.rest_sites[rj] - foot.rest_sites[ri]
        return wrap_angle(_heading(a) - _heading(pair) + _heading(foot.reference))

    def reference(self, side: str, foot_heading: float, held: float, positions: np.ndarray,
                  valid: np.ndarray | None, leg_now: np.ndarray | None) -> float:
        """The heading (radians) to hold the foot at: its target heading, or where both the
        actor's and the character's knees are bent, the heading that puts the character's
        knee plane on the actor's (the character's ankle has no axial turn, so a held foot's
        heading sets its knee plane: :math:`\\psi_t + (h - \\psi_c)` with :math:`\\psi` the
        knee planes' headings, :func:`knee_plane`, and :math:`h` the held heading), blended in
        as the knees bend from :data:`BEND_FROM` to :data:`BEND_FULL`."""
        leg = self._leg_rows.get(side)
        if leg is None or leg_now is None or (valid is not None and not bool(valid[leg].all())):
            return foot_heading
        psi_t, bend_t = knee_plane(*positions[leg])
        psi_c, bend_c = knee_plane(*leg_now)
        w = LEG_SHARE * smoothstep((min(bend_t, bend_c) - BEND_FROM) / (BEND_FULL - BEND_FROM))
        knee = wrap_angle(psi_t + wrap_angle(held - psi_c) - foot_heading)
        if not (w > 0.0 and abs(knee) <= MAX_KNEE_TURN):  # beyond it: a knee bending the other way (or lost)
            return foot_heading
        return wrap_angle(foot_heading + w * knee)

    def turns(self, positions: np.ndarray, orientations: np.ndarray | None, valid: np.ndarray | None,
              locked: np.ndarray, anchors: np.ndarray, legs_now: dict[str, np.ndarray] | None = None) -> dict[str, float]:
        """Side -> radians to turn that foot's holds by on this frame (0 where it is held at
        fewer than two points or has no target heading); ``legs_now``: side -> ``(3, 3)`` the
        character's hip, knee and ankle positions now."""
        out: dict[str, float] = {}
        for side, foot in self.feet.items():
            out[side] = 0.0
            target = self.target_heading(side, positions, orientations, valid)
            previous = self._previous.pop(side, None)
            held_sites = foot.sites[locked[foot.sites]]
            if target is None or held_sites.size < 2:
                continue
            held = self.held_heading(side, held_sites, anchors)
            aim = self.reference(side, target, held, positions, valid, (legs_now or {}).get(side))
            self._previous[side] = aim
            change = 0.0 if previous is None else wrap_angle(aim - previous)
            e = wrap_angle(held - aim)
            excess = e - min(max(e, -self.free), self.free)  # what np.clip does, on floats
            # the aim's own turn at once, in its own direction; besides, step_rate either way (an
            # aim wobbling about a fixed heading does not hurry a landing's error out)
            low, high = min(0.0, change) - self.step_rate, max(0.0, change) + self.step_rate
            out[side] = min(max(-excess, low), high)
        return out

