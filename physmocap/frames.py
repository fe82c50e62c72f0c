"""Segment orientations built from joint positions (for positional sources).

A tracker gives joint centres only; the IK's orientation targets need a frame
per segment.  Every function here returns rotation matrices ``(..., 3, 3)``
whose *columns* are the segment's x, y and z axes in world coordinates
(``v_world = R @ v_segment``), orthonormal and right-handed by construction:
the primary axis is normalised, the secondary one is made orthogonal to it
(Gram-Schmidt) and normalised, and the third is their cross product.

Axes follow the body-frame convention x forward, y left, z up (ROS REP 103,
MuJoCo's humanoids) for a person standing in the rest pose:

* :func:`pelvis_frame`: y along the hip line (right hip to left hip), z
  towards the spine, x = y x z forward.
* :func:`chest_frame`: y along the shoulder line, z up the trunk.
* :func:`head_frame`: z from neck to head, y from a lateral reference.
* :func:`limb_frame`: for a chain a -> b -> c (hip, knee, ankle), the frame
  of segment a-b: z from b to a (up the thigh when standing), y the normal of
  the limb plane ``(a - b) x (c - b)`` (the axis of the middle hinge joint),
  x = y x z.  For a knee flexing forward y points to the body's right; for
  an elbow flexing forward, to the body's left.

Degenerate input (coincident points, a straight limb) falls back to a given
axis instead of dividing by zero; the result is always finite.  Use
:func:`matrix_to_quat` for x-y-z-w quaternions.
"""

from __future__ import annotations

import numpy as np

from .rotations import Rotation
from .vectors import unit

__all__ = [
    "frame_from_axes",
    "pelvis_frame",
    "chest_frame",
    "head_frame",
    "limb_frame",
    "matrix_to_quat",
]

_EPS = 1e-9


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Normalise ``v (..., 3)``; where it is (near) zero use ``fallback``."""
    u, n = unit(v, _EPS)
    fb = np.broadcast_to(np.asarray(fallback, dtype=float), v.shape)
    return np.where(n[..., None] > _EPS, u, fb)


def _any_perpendicular(z: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to unit ``z (..., 3)`` (crossing the least aligned world axis)."""
    ref = np.zeros_like(z)
    idx = np.argmin(np.abs(z), axis=-1)
    np.put_along_axis(ref, idx[..., None], 1.0, axis=-1)
    return _unit(np.cross(z, ref), np.array([1.0, 0.0, 0.0]))


def frame_from_axes(
    primary: np.ndarray,
    secondary: np.ndarray,
    axes: str = "zy",
) -> np.ndarray:
    """Orthonormal right-handed frames from two direction fields.

    Args:
        primary: ``(..., 3)`` direction of the first axis named in ``axes`` (kept exactly).
        secondary: ``(..., 3)`` rough direction of the second axis (its part
            along the primary is removed).
        axes: Which axes they are: ``"zy"`` (z = primary, y = secondary,
            x = y x z), ``"yz"`` (y primary, z secondary), ``"zx"``, ``"xz"``.

    Returns:
        ``(..., 3, 3)`` rotation matrices with the axes as columns.
    """
    p = np.asarray(primary, dtype=float)
    s = np.asarray(secondary, dtype=float)
    p, s = np.broadcast_arrays(p, s)
    first = axes[0]
    default = {"x": [1.0, 0.0, 0.0], "y": [0.0, 1.0, 0.0], "z": [0.0, 0.0, 1.0]}[first]
    a = _unit(p, np.array(default))
    s_norm = np.linalg.norm(s, axis=-1, keepdims=True)
    r = s - np.sum(s * a, axis=-1, keepdims=True) * a
    # Secondary (nearly) parallel to the primary: its remainder is rounding noise.
    # (or too short to normalise at all: then any perpendicular will do)
    degenerate = np.linalg.norm(r, axis=-1, keepdims=True) <= np.maximum(1e-6 * s_norm, _EPS)
    b = np.where(degenerate, _any_perpendicular(a), _unit(r, np.zeros(3)))
    b = _unit(b - np.sum(b * a, axis=-1, keepdims=True) * a, np.zeros(3))  # second Gram-Schmidt pass
    if axes == "zy":
        z, y = a, b
        x = np.cross(y, z)
    elif axes == "yz":
        y, z = a, b
        x = np.cross(y, z)
    elif axes == "zx":
        z, x = a, b
        y = np.cross(z, x)
    elif axes == "xz":
        x, z = a, b
        y = np.cross(z, x)
    else:
        raise ValueError(f"axes must be one of 'zy', 'yz', 'zx', 'xz', got {axes!r}")
    return np.stack([x, y, z], axis=-1)


def pelvis_frame(
    left_hip: np.ndarray, right_hip: np.ndarray, spine_point: np.ndarray
) -> np.ndarray:
    """Pelvis frames ``(..., 3, 3)``: y along the hip line, z towards ``spine_point``.

    y = unit(left_hip - right_hip) exactly; z is the direction from the hip
    centre to ``spine_point`` (spine, chest, torso or neck) made orthogonal to
    y; x = y x z points forward.
    """
    left_hip = np.asarray(left_hip, dtype=float)
    right_hip = np.asarray(right_hip, dtype=float)
    mid = 0.5 * (left_hip + right_hip)
    return frame_from_axes(left_hip - right_hip, np.asarray(spine_point, dtype=float) - mid, "yz")


def chest_frame(
    left_shoulder: np.ndarray,
    right_shoulder: np.ndarray,
    top: np.ndarray,
    bottom: np.ndarray,
) -> np.ndarray:
    """Chest (thorax) frames: y along the shoulder line, z from ``bottom`` to ``top``.

    ``top`` is usually the neck and ``bottom`` the torso / spine / pelvis
    point.  y = unit(left_shoulder - right_shoulder) exactly, z = the trunk
    direction made orthogonal to y, x = y x z forward.
    """
    left = np.asarray(left_shoulder, dtype=float)
    right = np.asarray(right_shoulder, dtype=float)
    up = np.asarray(top, dtype=float) - np.asarray(bottom, dtype=float)
    return frame_from_axes(left - right, up, "yz")


def head_frame(neck: np.ndarray, head: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Head frames: z from ``neck`` to ``head`` exactly, y from ``lateral``.

    Two points fix only the head's direction, not its turn about it, so the
    lateral (left-pointing) axis comes from elsewhere, usually the chest
    frame's y column.  x = y x z is the facing.
    """
    z = np.asarray(head, dtype=float) - np.asarray(neck, dtype=float)
    return frame_from_axes(z, np.asarray(lateral, dtype=float), "zy")


def limb_frame(
    a: np.ndarray,
    b: np.ndarray,
    c: np.ndarray,
    fallback_axis: np.ndarray,
    straight_deg: float = 10.0,
    distal: bool = False,
) -> np.ndarray:
    """Frame of segment a-b of the chain a -> b -> c (e.g. hip, knee, ankle).

    z = unit(a - b) exactly (with ``distal``: the frame of segment b-c, z =
    unit(b - c), same y).  y is the limb-plane normal
    :math:`n = (a - b) \\times (c - b)`, normalised, which is ill-defined when
    the limb is nearly straight.  With :math:`s = \\sin\\theta` the sine of the
    angle between the two segments and :math:`s_0 = \\sin(\\text{straight\\_deg})`,

    .. math:: y \\propto w\\,\\hat n + (1 - w)\\, f_\\perp, \\qquad
              w = \\mathrm{smoothstep}(s / s_0 - 1)

    blends from the plane normal (``s >= 2 s_0``) to the fallback axis
    ``f`` (``s <= s_0``) without a jump.  Give ``fallback_axis`` the sense the
    plane normal has when the limb bends the normal way (for a knee: the
    body's right, ``-pelvis_y``; for an elbow: the body's left).

    Args:
        a, b, c: ``(..., 3)`` proximal, middle and distal joint positions.
        fallback_axis: ``(..., 3)`` or ``(3,)`` hinge direction for a straight limb.
        straight_deg: Bend angle below which the limb counts as straight.
        distal: Return the frame of the distal segment b-c instead.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = np.asarray(c, dtype=float)
    u = a - b
    v = c - b
    n = np.cross(u, v)
    denom = np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1)
    s = np.where(denom > _EPS, np.linalg.norm(n, axis=-1) / np.maximum(denom, _EPS), 0.0)
    s0 = np.sin(np.radians(straight_deg))
    t = np.clip(s / s0 - 1.0, 0.0, 1.0)
    w = (t * t * (3.0 - 2.0 * t))[..., None]
    z = _unit(-v if distal else u, np.array([0.0, 0.0, 1.0]))
    f = np.broadcast_to(np.asarray(fallback_axis, dtype=float), z.shape)
    f_perp = _unit(f - np.sum(f * z, axis=-1, keepdims=True) * z, np.zeros(3))
    n_hat = _unit(n, np.zeros(3))
    y = w * n_hat + (1.0 - w) * f_perp
    # If the normal and the fallback oppose each other mid-blend, y can cancel:
    # take whichever is defined, favouring the plane normal.
    y = np.where(np.linalg.norm(y, axis=-1, keepdims=True) > 1e-3, y, np.where(w > 0.5, n_hat, f_perp))
    return frame_from_axes(z, y, "zy")


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` to x-y-z-w quaternions ``(..., 4)``."""
    R = np.asarray(R, dtype=float)
    shape = R.shape[:-2]
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
    return q.reshape(*shape, 4)
