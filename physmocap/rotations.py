"""Rotation and axis conventions: the one place in physmocap that knows them.

Conventions used everywhere else in the package:

* Rotations are :class:`scipy.spatial.transform.Rotation` objects or quaternion
  arrays in scipy's **x-y-z-w** (scalar-last) order.  MuJoCo stores quaternions
  **w-x-y-z** (scalar-first); :func:`wxyz_to_xyzw` and :func:`xyzw_to_wxyz` are
  the only conversions between the two, and only the MuJoCo boundary calls them.
* Angles are radians inside; degrees only appear in files (BVH channels) and in
  printed reports.
* The world is **Z-up** (MuJoCo's convention), lengths are **metres**.  A file
  written Y-up is converted by :func:`up_axis_matrix` when it is read and when it
  is written; no other module rotates between up axes.
* A rotation ``R`` maps child-frame vectors into the parent frame:
  ``v_parent = R @ v_child``.  BVH channel orders are *intrinsic*: channels
  ``Zrotation Xrotation Yrotation`` mean ``R = Rz(a) @ Rx(b) @ Ry(c)``, which is
  scipy's upper-case sequence ``"ZXY"``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "Rotation",
    "cross",
    "hamilton",
    "quat_from_rotvec",
    "quat_to_rotvec",
    "rotate",
    "UP_AXES",
    "up_axis_matrix",
    "wxyz_to_xyzw",
    "xyzw_to_wxyz",
    "euler_to_quat",
    "quat_to_euler",
    "unwrap_euler",
    "quat_mul",
    "quat_apply",
    "quat_conj",
    "quat_canonical",
]

UP_AXES = ("Y", "Z")


def up_axis_matrix(src_up: str, dst_up: str) -> np.ndarray:
    """Return the 3x3 rotation that maps vectors from ``src_up`` to ``dst_up`` frames.

    Y-up to Z-up is +90 degrees about X: ``(x, y, z) -> (x, -z, y)``, so a Y-up
    file's +Y becomes +Z and its +Z (usually the performer's facing) becomes -Y.
    """
    src_up, dst_up = src_up.upper(), dst_up.upper()
    for axis in (src_up, dst_up):
        if axis not in UP_AXES:
            raise ValueError(f"up axis must be one of {UP_AXES}, got {axis!r}")
    y_to_z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    if src_up == dst_up:
        return np.eye(3)
    if (src_up, dst_up) == ("Y", "Z"):
        return y_to_z
    return y_to_z.T


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    """MuJoCo (w, x, y, z) quaternions to scipy (x, y, z, w); any leading shape."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """scipy (x, y, z, w) quaternions to MuJoCo (w, x, y, z); any leading shape."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def _check_order(order: str) -> str:
    order = order.upper()
    if len(order) != 3 or set(order) - set("XYZ") or len(set(order)) < 2:
        raise ValueError(f"rotation order must be three of X, Y, Z, got {order!r}")
    return order


def euler_to_quat(angles: np.ndarray, order: str, degrees: bool = False) -> np.ndarray:
    """Intrinsic Euler angles ``(..., 3)`` in ``order`` to quaternions ``(..., 4)`` xyzw.

    ``angles[..., i]`` is the angle about axis ``order[i]``; the rotation is
    ``R = R_order[0] @ R_order[1] @ R_order[2]`` (BVH channel order).

    Computed in closed form as the product of the three elementary
    quaternions ``q_i = (sin(a_i / 2) e_axis_i, cos(a_i / 2))``; this is the
    same rotation scipy's ``Rotation.from_euler(order, ...)`` gives, about ten
    times faster on large arrays (the BVH reader's hot path).
    """
    order = _check_order(order)
    if order[0] == order[1] or order[1] == order[2]:
        raise ValueError(f"rotation order must not repeat an axis consecutively, got {order!r}")
    angles = np.asarray(angles, dtype=float)
    if angles.shape[-1:] != (3,):
        raise ValueError(f"Euler angles must have shape (..., 3), got {angles.shape}")
    half = 0.5 * (np.deg2rad(angles) if degrees else angles)
    c, s = np.cos(half), np.sin(half)
    q = None
    for i, axis in enumerate(order):
        qi = np.zeros(angles.shape[:-1] + (4,))
        qi[..., "XYZ".index(axis)] = s[..., i]
        qi[..., 3] = c[..., i]
        q = qi if q is None else quat_mul(q, qi)
    return q


def quat_to_euler(q: np.ndarray, order: str, degrees: bool = False) -> np.ndarray:
    """Quaternions ``(..., 4)`` xyzw to intrinsic Euler angles ``(..., 3)`` in ``order``.

    The raw decomposition lies in scipy's principal range; pass the result of a
    frame sequence through :func:`unwrap_euler` to make it continuous.
    """
    order = _check_order(order)
    q = np.asarray(q, dtype=float)
    shape = q.shape[:-1]
    e = Rotation.from_quat(q.reshape(-1, 4)).as_euler(order, degrees=degrees)
    return e.reshape(*shape, 3)


def unwrap_euler(angles: np.ndarray, order: str, degrees: bool = False) -> np.ndarray:
    """Make intrinsic Euler angles ``(F, ..., 3)`` continuous along axis 0.

    Each Euler triple has two equivalent solutions for proper (Tait-Bryan)
    sequences: ``(a, b, c)`` and ``(a + pi, pi - b, c + pi)``.  For every frame
    the solution closest to the previous frame is chosen, then each angle is
    shifted by a multiple of 2*pi to lie within pi of the previous frame's.  The
    rotations encoded are unchanged; only their numbers move.  The first frame
    is kept as given.

    Vectorised over frames: the closest solution at frame ``t`` depends only on
    which solution frame ``t - 1`` took (distances are taken modulo whole
    turns), so each frame is a map from the previous choice to its own
    (constant, keep or swap); the choices are composed with cumulative sums,
    and the whole-turn shifts are a cumulative sum of rounded differences.
    """
    order = _check_order(order)
    v = np.array(angles, dtype=float, copy=True)
    F = v.shape[0]
    if F < 2:
        return v
    full = 360.0 if degrees else 2.0 * np.pi
    half = full / 2.0
    alt = v.copy()
    alt[..., 0] += half
    alt[..., 1] = (half - v[..., 1]) if len(set(order)) == 3 else -v[..., 1]
    alt[..., 2] += half

    def dist(prev: np.ndarray, cand: np.ndarray) -> np.ndarray:
        d = prev - cand
        return np.abs(d - np.round(d / full) * full).sum(axis=-1)

    # Choice at frame t (True: the alternative) if frame t-1 chose (0) the given
    # solution or (1) the alternative.  Index u = t - 1.
    after0 = dist(v[:-1], alt[1:]) < dist(v[:-1], v[1:])
    after1 = dist(alt[:-1], alt[1:]) < dist(alt[:-1], v[1:])
    const = after0 == after1
    swap = ~const & after0
    frame = np.arange(1, F).reshape((-1,) + (1,) * (const.ndim - 1))
    last = np.maximum.accumulate(np.where(const, frame, 0), axis=0)  # last constant frame (0: frame 0)
    parity = np.cumsum(swap, axis=0) % 2
    r = np.maximum(last - 1, 0)
    base = np.where(last > 0, np.take_along_axis(after0, r, axis=0), False)
    base_parity = np.where(last > 0, np.take_along_axis(parity, r, axis=0), 0)
    choice = np.zeros(v.shape[:-1], dtype=bool)
    choice[1:] = base ^ ((parity - base_parity) % 2).astype(bool)
    chosen = np.where(choice[..., None], alt, v)
    turns = np.zeros_like(chosen)
    turns[1:] = np.cumsum(np.round((chosen[:-1] - chosen[1:]) / full), axis=0)
    return chosen + turns * full


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (inverse for unit quaternions), xyzw."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([-q[..., :3], q[..., 3:4]], axis=-1)


def _single(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``a`` and ``b`` each hold one vector (shapes ``(k,)`` or ``(1, ..., 1, k)``)."""
    return a.size == a.shape[-1] and b.size == b.shape[-1]


def _parts(x: np.ndarray, single: bool) -> list:
    """Components of ``x`` along its last axis: Python floats for a vector ``(k,)``, or for
    any single vector when ``single`` (:func:`_single`: the same IEEE products and sums as
    numpy's, without numpy's overhead on every small operation), else views ``x[..., i]``."""
    return x.ravel().tolist() if single or x.ndim == 1 else [x[..., i] for i in range(x.shape[-1])]


def _joined(parts: list, a: np.ndarray, b: np.ndarray, single: bool) -> np.ndarray:
    """The components of :func:`_parts` of ``a`` and ``b`` combined, stacked back along the
    last axis, shaped as ``a`` and ``b`` broadcast."""
    if single:
        out = np.array(parts)
        lead = max(a.ndim, b.ndim) - 1
        return out.reshape((1,) * lead + out.shape) if lead else out
    return np.stack(parts, axis=-1)


def hamilton(a: Sequence, b: Sequence) -> list:
    """The Hamilton product of quaternions given by their x-y-z-w components (Python floats,
    or arrays that broadcast): its four components.  The one place the product is written;
    :func:`quat_mul` and per-joint loops (``motion``'s one-frame kinematics) use it."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]


def rotate(q: Sequence, v: Sequence) -> list:
    """Vector ``v`` rotated by the unit quaternion ``q``, both by their components (x-y-z-w;
    floats or arrays that broadcast): :math:`v' = v + w t + u \times t` with
    :math:`t = 2 u \times v`.  The one place the rotation is written (see :func:`hamilton`)."""
    ux, uy, uz, w = q
    vx, vy, vz = v
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return [vx + w * tx + (uy * tz - uz * ty), vy + w * ty + (uz * tx - ux * tz), vz + w * tz + (ux * ty - uy * tx)]


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of xyzw quaternions, broadcasting (rotation ``Ra @ Rb``)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    single = _single(a, b)
    return _joined(hamilton(_parts(a, single), _parts(b, single)), a, b, single)


def quat_apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` xyzw, broadcasting."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    # components written out (:func:`rotate`): np.cross is slow
    single = _single(q, v)
    return _joined(rotate(_parts(q, single), _parts(v, single)), q, v, single)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products ``a x b`` of 3-vectors ``(..., 3)``, broadcasting: ``np.cross``'s
    values bit for bit (its products and differences, in its order), without its overhead
    (a tenth of the time on one vector)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    single = _single(a, b)
    ax, ay, az = _parts(a, single)
    bx, by, bz = _parts(b, single)
    return _joined([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], a, b, single)


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """Unit quaternions with a non-negative scalar part (w >= 0), xyzw."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def quat_from_rotvec(v: np.ndarray) -> np.ndarray:
    r"""Unit quaternions (x-y-z-w) of rotation vectors ``v (..., 3)`` (axis times angle,
    radians): :math:`(\hat v \sin(\theta/2), \cos(\theta/2))`, :math:`\theta = |v|`
    (the sine's series :math:`\tfrac12 - \theta^2/48` below a microradian); what
    ``Rotation.from_rotvec(v).as_quat()`` gives, to round-off, without its overhead."""
    v = np.asarray(v, dtype=float)
    angle = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    small = angle < 1e-6
    scale = np.where(small, 0.5 - angle * angle / 48.0, np.sin(0.5 * angle) / np.where(small, 1.0, angle))
    return np.concatenate([v * scale, np.cos(0.5 * angle)], axis=-1)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    r"""Rotation vectors ``(..., 3)`` (axis times angle, radians, the angle in
    :math:`[0, \pi]`) of quaternions ``q (..., 4)`` x-y-z-w (normalised here):
    :math:`\theta = 2 \operatorname{atan2}(|u|, w)` on the canonical sign :math:`w \ge 0`,
    :math:`v = u\, \theta / |u|` (the series :math:`2 + \theta^2/12` below a
    microradian); what ``Rotation.from_quat(q).as_rotvec()`` gives, to round-off."""
    q = quat_canonical(q)
    n = np.sqrt(np.sum(q[..., :3] * q[..., :3], axis=-1, keepdims=True))
    angle = 2.0 * np.arctan2(n, q[..., 3:4])
    small = angle < 1e-6
    scale = np.where(small, 2.0 + angle * angle / 12.0, angle / np.where(small, 1.0, n))
    return q[..., :3] * scale


def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    r"""Smallest rotations (x-y-z-w) taking directions ``a (..., 3)`` onto ``b (..., 3)``.

    :math:`q = (\hat n \sin(\theta/2), \cos(\theta/2))` with
    :math:`\hat n = \widehat{a \times b}` and :math:`\theta = \operatorname{atan2}(|a \times b|, a \cdot b)`;
    identity where either vector is zero or they are parallel (antiparallel
    vectors, where the axis is undefined, also give the identity).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    axis = cross(a, b)
    s = np.linalg.norm(axis, axis=-1, keepdims=True)
    c = np.sum(a * b, axis=-1, keepdims=True)
    theta = np.arctan2(s, c)
    ok = (s > 1e-12) & (np.linalg.norm(a, axis=-1, keepdims=True) > 1e-12)
    n = np.where(ok, axis / np.maximum(s, 1e-12), 0.0)
    half = np.where(ok, 0.5 * theta, 0.0)
    return np.concatenate([n * np.sin(half), np.cos(half)], axis=-1)
