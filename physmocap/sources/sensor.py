"""Sensor conventions of joint-position trackers, handled in one place.

From the file to physmocap's world (metres, Z-up, floor at z = 0):

1. **Units.**  Trackers write millimetres (OpenNI/NITE, Azure Kinect) or
   metres (Kinect v2).  :func:`unit_scale` knows ``m``, ``cm``, ``mm`` and
   ``inch``; ``"auto"`` (:func:`guess_units`) looks at the size of the
   body: the median distance of the joints from their centroid is 0.3 to
   0.5 m for an adult, so it reads hundreds in mm, tens in cm and below 1
   in m (thresholds 100 and 2).
2. **Camera frame** (``frame="camera"``): Y up, Z away from the camera
   (depth), X horizontal.  In a *mirrored* view (OpenNI with mirroring on,
   the Kinect SDKs' camera space) +X points to the performer's right as they
   face the camera, i.e. the camera's left, and (X, Y, Z) is right-handed.
   An unmirrored view has +X to the camera's right: a left-handed frame,
   made right-handed by negating X.  Then Y-up becomes Z-up with
   :func:`physmocap.rotations.up_axis_matrix` (camera depth +Z -> world -Y).
   ``frame="world"`` takes the data as a world frame with the given up axis.
3. **Up axis and floor** (:func:`estimate_ground`).  A tilted camera's Y is
   not the world's up.  Over the clip, the lower foot of each frame that is
   nearly still is on the ground (stance); those points lie on a plane
   parallel to the floor.  Their principal directions are found by SVD:
   directions along which the stance points spread out (> ``min_spread`` m
   standard deviation) lie in the floor, so the up axis is perpendicular to
   them; directions without spread are left to the body's own axis (the
   median direction from the feet to the neck/head), which fixes the tilt
   that a single straight walking line cannot.  The floor is then a low
   percentile of the stance feet's heights minus the foot joint's height
   above the ground (:func:`default_foot_height`).  Both can be given
   instead (``floor_plane=(a, b, c, d)`` in file coordinates, ``floor=``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import OptionError
from ..rotations import Rotation, up_axis_matrix

__all__ = [
    "UNIT_SCALES",
    "unit_scale",
    "guess_units",
    "to_world",
    "Ground",
    "estimate_ground",
    "level_rotation",
    "default_foot_height",
]

#: Metres per unit: the same names as the BVH reader's (``--in-units`` takes them for
#: every reader); ``cmu`` is :data:`physmocap.sources.bvh.CMU_UNIT`.
UNIT_SCALES: dict[str, float] = {
    "m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "ft": 0.3048, "cmu": 2.54 / 45.0,
}  # fmt: skip
_UNIT_ALIASES = {
    "meter": "m", "meters": "m", "metre": "m", "metres": "m",
    "centimeter": "cm", "centimeters": "cm", "centimetre": "cm", "centimetres": "cm",
    "millimeter": "mm", "millimeters": "mm", "millimetre": "mm", "millimetres": "mm",
    "in": "inch", "inches": "inch", "foot": "ft", "feet": "ft",
}  # fmt: skip

#: Winter (2009), Biomechanics and Motor Control of Human Movement, fig. 4.1:
#: ankle joint height 0.039 H, hip (greater trochanter) 0.530 H, so the ankle
#: sits 0.039 / (0.530 - 0.039) of the hip-to-ankle length above the floor.
ANKLE_HEIGHT_PER_LEG = 0.039 / (0.530 - 0.039)
#: Height of the ball-of-foot joint centre above the floor (about the radius
#: of the metatarsal heads), metres.
TOE_HEIGHT = 0.02


def unit_scale(units: str | float | None, path: str | os.PathLike | None = None) -> tuple[str, float]:
    """``(name, metres per unit)`` for a unit name or a number of metres per unit."""
    if units is None:
        return "m", 1.0
    if isinstance(units, (int, float)) and not isinstance(units, bool):
        if not (math.isfinite(units) and units > 0):
            raise OptionError(f"units must be positive metres per unit, got {units}", path=path)
        return f"{float(units):g} m", float(units)
    name = str(units).strip().lower()
    name = _UNIT_ALIASES.get(name, name)
    if name in UNIT_SCALES:
        return name, UNIT_SCALES[name]
    try:
        return unit_scale(float(name), path)
    except ValueError:
        pass
    known = ", ".join(UNIT_SCALES)
    raise OptionError(f"unknown length unit {units!r}; use one of {known}, auto, or metres per unit", path=path)


def guess_units(positions: np.ndarray) -> str:
    """``"m"``, ``"cm"`` or ``"mm"`` from the body's size (see the module docstring)."""
    p = np.asarray(positions, dtype=float)
    with np.errstate(invalid="ignore"):
        centre = np.nanmean(p, axis=1, keepdims=True) if p.size else p
        d = np.linalg.norm(p - centre, axis=-1)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return "m"
    size = float(np.median(d))
    if size > 100.0:
        return "mm"
    if size > 2.0:
        return "cm"
    return "m"


def to_world(
    positions: np.ndarray,
    frame: str = "camera",
    up: str = "Y",
    mirrored: bool = True,
) -> np.ndarray:
    """Positions (metres) in the file's frame -> a right-handed Z-up frame.

    Args:
        positions: ``(..., 3)``.
        frame: ``"camera"`` (Y up, Z depth; see the module docstring) or ``"world"``.
        up: The up axis of a world frame, ``"Y"`` or ``"Z"`` (a camera frame is Y-up).
        mirrored: Camera frame only: True if +X points to the performer's right.
    """
    p = np.asarray(positions, dtype=float)
    frame = frame.lower()
    if frame == "camera":
        if not mirrored:
            p = p * np.array([-1.0, 1.0, 1.0])
        return p @ up_axis_matrix("Y", "Z").T
    if frame == "world":
        return p @ up_axis_matrix(up.upper(), "Z").T
    raise OptionError(f"frame must be 'camera' or 'world', got {frame!r}")


def level_rotation(up: np.ndarray) -> np.ndarray:
    """The smallest rotation (3x3) taking the unit vector ``up`` to +Z."""
    u = np.asarray(up, dtype=float)
    u = u / np.linalg.norm(u)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(u, z)
    s = np.linalg.norm(axis)
    c = float(np.dot(u, z))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def default_foot_height(kind: str, leg_length: float | None) -> float:
    """Height (m) above the floor of a standing foot's lowest tracked joint.

    ``kind`` is its canonical stem: ``"ankle"`` (Winter's ratio times the
    hip-to-ankle length, about 7 cm for an adult), ``"toe"`` (2 cm), and 0 for
    anything else (``toe_end``, or a joint of unknown kind).
    """
    if kind == "ankle" and leg_length is not None and math.isfinite(leg_length) and leg_length > 0:
        return ANKLE_HEIGHT_PER_LEG * leg_length
    if kind == "toe":
        return TOE_HEIGHT
    return 0.0


@dataclass
class Ground:
    """The estimated ground: up axis, floor height, and how they were found.

    Attributes:
        up: ``(3,)`` unit up vector in the input frame.
        floor: Height of the floor along ``up`` (metres, input frame origin).
        method: ``"plane"``, ``"line+body"``, ``"body"`` or ``"given"``.
        stance_points: How many stance samples were used.
        spread: ``(3,)`` standard deviations of the stance points along their principal axes.
    """

    up: np.ndarray
    floor: float
    method: str
    stance_points: int = 0
    spread: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation(self) -> np.ndarray:
        """The rotation that levels the input frame (``up`` -> +Z)."""
        return level_rotation(self.up)


def estimate_ground(
    positions: np.ndarray,
    valid: np.ndarray,
    feet: list[int],
    top: list[int],
    fps: float,
    foot_height: float = 0.0,
    prior_up: np.ndarray = np.array([0.0, 0.0, 1.0]),
    min_spread: float = 0.3,
    max_foot_speed: float = 0.5,
    floor_percentile: float = 10.0,
) -> Ground:
    """Up axis and floor height from a clip's feet (see the module docstring).

    Args:
        positions: ``(F, J, 3)`` finite positions in metres, roughly Z-up.
        valid: ``(F, J)`` which samples are real measurements.
        feet: Indices of the lowest tracked joint of each leg (one or two).
        top: Indices of upper-body joints (neck, head...) for the body axis.
        fps: Frame rate (for the foot speed).
        foot_height: Height of the foot joints above the floor when standing.
        prior_up: Up direction to start from (the converted camera's Y).
        min_spread: Standard deviation (m) along which stance points count as spanning the floor.
        max_foot_speed: A lower foot slower than this (m/s) is taken as standing.
        floor_percentile: Percentile of the stance heights taken as standing height.
    """
    P = np.asarray(positions, dtype=float)
    V = np.asarray(valid, dtype=bool)
    F = P.shape[0]
    u0 = np.asarray(prior_up, dtype=float)
    u0 = u0 / np.linalg.norm(u0)
    if not feet:
        return Ground(up=u0, floor=float(np.percentile(P[..., :] @ u0, 1.0)), method="body")

    # Body axis: the median direction from the mean foot to the mean top joint.
    body = u0
    if top:
        feet_ok = V[:, feet].all(axis=1)
        top_ok = V[:, top].all(axis=1)
        ok = feet_ok & top_ok
        if ok.sum() >= 3:
            axis = P[ok][:, top].mean(axis=1) - P[ok][:, feet].mean(axis=1)
            n = np.linalg.norm(axis, axis=-1, keepdims=True)
            axis = axis[n[:, 0] > 1e-6] / n[n[:, 0] > 1e-6]
            if len(axis) and np.dot(np.median(axis, axis=0), u0) > 0.3:
                body = np.median(axis, axis=0)
                body = body / np.linalg.norm(body)

    # Stance points: per frame the lower valid foot, if it is nearly still.
    h = P[:, feet] @ body  # (F, nfeet)
    h = np.where(V[:, feet], h, np.inf)
    low = np.argmin(h, axis=1)
    has = np.isfinite(h.min(axis=1))
    foot_idx = np.asarray(feet)[low]
    pts = P[np.arange(F), foot_idx]
    speed = np.full(F, np.inf)
    if F > 2:
        vel = np.zeros_like(pts)
        vel[1:-1] = (pts[2:] - pts[:-2]) * (fps / 2.0)
        same = (foot_idx[2:] == foot_idx[:-2]) & has[2:] & has[:-2]
        speed[1:-1] = np.where(same, np.linalg.norm(vel[1:-1], axis=-1), np.inf)
    stance = has & (speed < max_foot_speed)
    if stance.sum() < max(10, F // 20):
        stance = has
    S = pts[stance]
    method = "body"
    up = body
    spread = (0.0, 0.0, 0.0)
    if len(S) >= 3:
        c = S.mean(axis=0)
        _, sv, Vt = np.linalg.svd(S - c, full_matrices=False)
        std = sv / math.sqrt(len(S))
        spread = tuple(float(x) for x in np.pad(std, (0, 3 - len(std))))
        if len(std) == 3 and std[1] > min_spread:
            up = Vt[2]
            method = "plane"
        elif std[0] > min_spread:
            d = Vt[0]
            up = body - np.dot(body, d) * d
            up = up / np.linalg.norm(up)
            method = "line+body"
        if np.dot(up, body) < 0:
            up = -up
    heights = S @ up if len(S) else (P.reshape(-1, 3) @ up)
    floor = float(np.percentile(heights, floor_percentile)) - float(foot_height)
    return Ground(up=up, floor=floor, method=method, stance_points=int(len(S)), spread=spread)  # type: ignore[arg-type]
