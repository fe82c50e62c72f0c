r"""Cubic Hermite bridges in rotation space, for one span or for many windows at once.

A bridge over the ``n`` frames strictly between two good frames :math:`a` and
:math:`b = a + n + 1` lives in the tangent space at :math:`q_a`: with
:math:`p_1 = \log(q_a^{-1} q_b)`, end velocities :math:`v_0, v_1` (radians per frame, in the
same tangent space) and :math:`s_i = i / (n + 1)`,

.. math::  p(s) = h_{10}(s)(n + 1) v_0 + h_{01}(s) p_1 + h_{11}(s)(n + 1) v_1, \qquad
           q_i = q_a \exp(p(s_i))

(:math:`h_{00}, h_{10}, h_{01}, h_{11}` the Hermite basis), so the curve leaves :math:`q_a` and
reaches :math:`q_b` at the joint's own speed.
"""

from __future__ import annotations

import numpy as np

from ..rotations import Rotation, quat_conj, quat_mul

__all__ = ["curve", "log_between", "windows"]


def log_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    r"""``(..., 3)``: :math:`\log(a^{-1} b)` for quaternions ``a, b (..., 4)`` (broadcast), the
    turn from ``a`` to ``b`` as a rotation vector (radians) in ``a``'s frame."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    d = quat_mul(quat_conj(a), b)
    return Rotation.from_quat(d.reshape(-1, 4)).as_rotvec().reshape(d.shape[:-1] + (3,))


def curve(first: np.ndarray, p1: np.ndarray, v0: np.ndarray, v1: np.ndarray, n: int) -> np.ndarray:
    r"""``(n, ..., 4)``: the Hermite bridge's inner rotations (module docstring) from ``first
    (..., 4)``, :math:`q_a`, with :math:`p_1` and the end velocities ``v0, v1 (..., 3)``, every
    argument in the tangent space at ``first`` (any leading shape, broadcast)."""
    span = float(n + 1)
    s = (np.arange(1, n + 1) / span).reshape((n,) + (1,) * np.ndim(p1))
    h10, h01, h11 = s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    p = h10 * span * v0 + h01 * p1 + h11 * span * v1
    rot = Rotation.from_rotvec(p.reshape(-1, 3)).as_quat().reshape(p.shape[:-1] + (4,))
    return quat_mul(np.broadcast_to(first, rot.shape), rot)


def windows(q: np.ndarray, starts: np.ndarray, n: int) -> np.ndarray:
    r"""``(W, n, K, 4)``: the Hermite bridge of every joint of ``q (F, K, 4)`` over each
    window of ``n`` frames starting at ``starts (W,)`` (frames ``starts - 2`` and
    ``starts + n + 1`` must be in the clip: the end velocities are the one-frame turns just
    outside, :math:`v_0 = \log(q_{a-1}^{-1} q_a)` and :math:`v_1 = \log(q_a^{-1} q_{b+1}) - p_1`)."""
    starts = np.asarray(starts, dtype=int)
    qa, qb = q[starts - 1], q[starts + n]
    p1 = log_between(qa, qb)
    v0 = -log_between(qa, q[starts - 2])
    v1 = log_between(qa, q[starts + n + 1]) - p1
    return np.moveaxis(curve(qa, p1, v0, v1, n), 0, 1)
