r"""Floor contacts other than the feet: knees, hands and the pelvis.

An actor kneeling, crawling, sitting on the floor or pushing up from it rests
other body parts on the floor.  They are detected on the actor like the feet
(:class:`~physmocap.ik.contacts.ContactDetector`: hysteresis on the height
above the floor and on the horizontal speed, minimum durations), with
heights that scale with the actor's size, and honoured like the feet by the
offline plan (:func:`~physmocap.ik.footplan.plant_body_contacts`): the joint's
target holds one location during the contact and is pulled onto the floor, and
the floor constraint decides how low the character's own geometry lets it go.

Contact parts (:data:`BODY_PARTS`) and the joints measured:

* ``left_knee`` / ``right_knee``: the knee joint centre;
* ``left_hand`` / ``right_hand``: the lower of the wrist and the hand end
  (whichever the source has);
* ``pelvis``: the midpoint of the hip joint centres.

Thresholds (:class:`BodyContactOptions`) are fractions of the actor's leg
length :math:`L` (median hip-to-knee plus knee-to-ankle), so they hold for any
actor size and unit.  For :math:`L = 0.85` m the defaults enter a knee contact
below 10 cm and leave above 13 cm, a hand contact below 6 cm (leave 8.5 cm),
a pelvis contact below 17 cm (leave 21 cm).  A joint centre sits above the
floor by the flesh around it: about 5-8 cm for a kneeling knee, 2-4 cm for a
wrist with the palm flat, 8-12 cm for hip joints when sitting (Dempster-style
segment proportions).  Units: metres, seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..errors import OptionError
from ..options import check_fields
from .contacts import ContactDetector, ContactOptions, FloorPlane, central_velocity
from .easing import smoothstep

__all__ = ["BODY_PARTS", "BodyContactOptions", "detect_body_contacts", "body_part_points", "BodyContactStream", "BodyContactAnchor", "release_kneeling_feet"]

#: Contact part -> the canonical joints measured (the lowest of them counts).
BODY_PARTS: dict[str, tuple[str, ...]] = {
    "left_knee": ("left_knee",),
    "right_knee": ("right_knee",),
    "left_hand": ("left_wrist", "left_hand_end"),
    "right_hand": ("right_wrist", "right_hand_end"),
    "pelvis": ("left_hip", "right_hip"),
}


@dataclass(frozen=True)
class BodyContactOptions:
    """Thresholds of body-part contact detection, as fractions of the actor's leg length.

    Attributes:
        enabled: Detect knee, hand and pelvis contacts at all.
        knee_enter, knee_exit: Knee joint height (fraction of leg length) to enter / leave.
        hand_enter, hand_exit: Lower of wrist and hand end, to enter / leave.
        pelvis_enter, pelvis_exit: Mid-hip height, to enter / leave.
        speed_enter: Enter only below this horizontal speed (m/s).
        speed_exit: Leave above this horizontal speed (m/s).
        min_contact: The enter condition must hold this long (s).
        min_gap: The leave condition must hold this long (s).
    """

    enabled: bool = True
    knee_enter: float = 0.12
    knee_exit: float = 0.15
    hand_enter: float = 0.07
    hand_exit: float = 0.10
    pelvis_enter: float = 0.20
    pelvis_exit: float = 0.25
    speed_enter: float = 0.30
    speed_exit: float = 0.80
    min_contact: float = 0.10
    min_gap: float = 0.05

    def __post_init__(self) -> None:
        check_fields(self, "body contact")
        for part in ("knee", "hand", "pelvis"):
            if getattr(self, f"{part}_enter") > getattr(self, f"{part}_exit"):
                raise OptionError(f"body contact option {part}_enter must not exceed {part}_exit (hysteresis)")
        if self.speed_enter > self.speed_exit:
            raise OptionError("body contact option speed_enter must not exceed speed_exit (hysteresis)")

    def detector_options(self, part: str, leg: float) -> ContactOptions:
        """The :class:`ContactOptions` that detect ``part`` for a leg of ``leg`` metres."""
        kind = "pelvis" if part == "pelvis" else part.split("_", 1)[1]
        enter, leave = getattr(self, f"{kind}_enter") * leg, getattr(self, f"{kind}_exit") * leg
        return ContactOptions(
            heel_height_enter=enter,
            heel_height_exit=leave,
            speed_enter=self.speed_enter,
            heel_speed_exit=self.speed_exit,
            heel_lift_speed=math.inf,
            min_contact=self.min_contact,
            min_gap=self.min_gap,
        )


def body_part_points(world: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Contact part -> ``(F, 3)`` the point measured (see the module docstring), for the
    parts whose joints are in ``world`` (canonical joint -> ``(F, 3)``; a hand needs its
    wrist or hand end, the pelvis both hips)."""
    out: dict[str, np.ndarray] = {}
    for part, joints in BODY_PARTS.items():
        present = [j for j in joints if j in world]
        if not present or (part == "pelvis" and len(present) < len(joints)):
            continue
        pts = np.stack([np.asarray(world[j], dtype=float) for j in present], axis=1)
        if part == "pelvis":
            out[part] = pts.mean(axis=1)
        else:
            lowest = np.argmin(pts[..., 2], axis=1)
            out[part] = pts[np.arange(pts.shape[0]), lowest]
    return out


def _leg_length(world: Mapping[str, np.ndarray]) -> float | None:
    lengths = []
    for side in ("left", "right"):
        h, k, a = (world.get(f"{side}_{j}") for j in ("hip", "knee", "ankle"))
        if h is None or k is None or a is None:
            continue
        leg = np.linalg.norm(k - h, axis=-1) + np.linalg.norm(a - k, axis=-1)
        leg = leg[np.isfinite(leg)]
        if leg.size:
            lengths.append(float(np.median(leg)))
    return max(lengths) if lengths else None


def detect_body_contacts(
    world: Mapping[str, np.ndarray],
    fps: float,
    floor: FloorPlane,
    options: BodyContactOptions | None = None,
) -> dict[str, np.ndarray]:
    """Contact part -> ``(F,)`` bool: knees, hands and pelvis resting on the floor.

    Args:
        world: Canonical joint -> ``(F, 3)`` actor positions (metres, Z-up).
        fps: Frame rate.
        floor: The actor's floor (from the foot contact detection).
        options: Thresholds.

    Returns:
        Labels for the parts whose joints are present (none without legs).
    """
    opt = options or BodyContactOptions()
    leg = _leg_length(world)
    if not opt.enabled or leg is None or leg <= 0:
        return {}
    out: dict[str, np.ndarray] = {}
    for part, p in body_part_points(world).items():
        height = floor.heights(p)
        speed = np.linalg.norm(central_velocity(p, fps)[:, :2], axis=1)
        det = ContactDetector(["heel"], fps, opt.detector_options(part, leg))
        det.run(height[:, None], speed[:, None])
        det.finish()
        lab = np.zeros(p.shape[0], dtype=bool)
        for _, since, state in det.transitions:
            lab[since:] = state
        out[part] = lab
    return out


class BodyContactStream:
    """Causal knee, hand and pelvis contact detection, one frame at a time (streaming).

    The same thresholds as :func:`detect_body_contacts`, with the leg length and the
    floor known beforehand (the streaming retargeter's calibration); horizontal speed
    from a bounded look-behind, as :class:`~physmocap.ik.contacts.ContactStream` does.

    Args:
        parts: Contact parts to watch (keys of :data:`BODY_PARTS`).
        fps: Frame rate.
        floor: The actor's floor.
        leg: The actor's leg length (metres).
        options: Thresholds.
    """

    def __init__(
        self,
        parts: list[str],
        fps: float,
        floor: FloorPlane,
        leg: float,
        options: BodyContactOptions | None = None,
    ) -> None:
        opt = options or BodyContactOptions()
        self.parts = tuple(parts) if opt.enabled and leg > 0 else ()
        self.fps = float(fps)
        self.floor = floor
        self.detectors = [ContactDetector(["heel"], fps, opt.detector_options(p, leg)) for p in self.parts]
        self.window = max(1, int(round(0.035 * fps)))
        self.history: list[np.ndarray] = []

    @classmethod
    def for_actor(cls, world: Mapping[str, np.ndarray], fps: float, floor: FloorPlane, options=None):
        """The stream for the parts present in ``world`` (canonical joint -> ``(F, 3)``,
        a calibration frame or more), leg length measured there."""
        leg = _leg_length(world) or 0.0
        return cls(list(body_part_points(world)), fps, floor, leg, options)

    def step(self, world: Mapping[str, np.ndarray]) -> dict[str, bool]:
        """This frame's canonical joint positions (``(3,)`` each) in; part -> in contact out."""
        if not self.parts:
            return {}
        pts = body_part_points({k: np.asarray(v, dtype=float)[None] for k, v in world.items()})
        x = np.stack([pts[p][0] for p in self.parts])
        self.history.append(x)
        if len(self.history) > self.window + 1:
            self.history.pop(0)
        span = max(len(self.history) - 1, 1)
        speed = np.linalg.norm((x - self.history[0])[:, :2], axis=1) * (self.fps / span)
        height = self.floor.heights(x)
        out = {}
        for k, part in enumerate(self.parts):
            out[part] = bool(self.detectors[k].step(height[k : k + 1], speed[k : k + 1])[0])
        return out


class BodyContactAnchor:
    r"""Causal offset that holds one body part's targets on the floor during its contact.

    When the contact begins, the anchor is where the part's (first) joint target is
    horizontally, and the floor height vertically; the offset
    :math:`o = (A_{xy} - x_{xy},\; z_{floor} - x_z)` eases in over ``onset_time``
    (a knee seen 10 cm above the floor is lowered, not dropped) and, after the
    contact, fades back to zero along a smoothstep over ``release_time``.
    """

    def __init__(self, fps: float, onset_time: float = 0.1, release_time: float = 0.25, floor: float = 0.0) -> None:
        self.onset = max(1, int(round(onset_time * fps)))
        self.release = max(1, int(round(release_time * fps)))
        self.floor = float(floor)
        self.anchor: np.ndarray | None = None
        self.offset = np.zeros(3)
        self._age = 0
        self._fade_from = np.zeros(3)
        self._fade_left = 0

    def step(self, label: bool, point: np.ndarray) -> np.ndarray:
        """This frame's label and the part's (unshifted) target point ``(3,)``; returns the
        offset ``(3,)`` to add to the part's joint targets."""
        x = np.asarray(point, dtype=float)
        if label:
            if self.anchor is None:
                self.anchor = x[:2].copy()
                self._age = 0
            self._age += 1
            full = np.array([*(self.anchor - x[:2]), self.floor - x[2]])
            w = smoothstep(self._age / self.onset)
            self.offset = (1.0 - w) * self.offset + w * full if self._age < self.onset else full
            self._fade_left = 0
            return self.offset.copy()
        if self.anchor is not None:  # released: fade out from here
            self.anchor = None
            self._fade_from = self.offset.copy()
            self._fade_left = self.release
        if self._fade_left > 0:
            self._fade_left -= 1
            self.offset = self._fade_from * smoothstep(self._fade_left / self.release)
        else:
            self.offset = np.zeros(3)
        return self.offset.copy()


def release_kneeling_feet(labels: Mapping[str, object], body_labels: Mapping[str, object]) -> dict[str, object]:
    """Foot labels with each foot's contacts cleared while its knee rests on the floor.

    A kneeling leg's foot lies on its instep or on tucked toes: holding its sole sites on
    the floor would twist the ankle beyond its range, so the foot is left to the floor
    constraint while the knee is down.  Works on whole-clip ``(F,)`` arrays and on one
    frame's bools alike (same type out as in)."""
    out = dict(labels)
    for side in ("left", "right"):
        knee = body_labels.get(f"{side}_knee")
        if knee is None or not np.any(knee):
            continue
        for name in ("heel", "toe"):
            key = f"{side}_{name}"
            if key in out:
                v = np.asarray(out[key], dtype=bool) & ~np.asarray(knee, dtype=bool)
                out[key] = bool(v) if v.ndim == 0 else v
    return out
