"""Vectors along the last axis of an array: directions whose length may vanish.

A direction that may be degenerate (a segment whose ends coincide, a limb plane of a straight
limb, a lost joint's NaN) is normalised here, by :func:`unit` (with its length, to tell) or
:func:`direction`; what a near-zero vector becomes is the caller's choice (``eps``, or a
fallback where the length is below it).  A vector known to be long (a rest-pose bone, a
quaternion read back from a solver) is divided by its norm where it is.  Lengths in the
input's units (metres inside).
"""

from __future__ import annotations

import numpy as np

__all__ = ["unit", "direction"]


def unit(v: np.ndarray, eps: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    r"""``(u, n)``: :math:`u = v / \max(\lVert v\rVert, \varepsilon)` and :math:`n = \lVert v\rVert`
    along the last axis (``u`` shaped as ``v``, ``n`` without its last axis).  A vector shorter
    than ``eps`` comes out shorter than one (no division by zero); test ``n`` to tell.  The
    length is ``np.linalg.norm``'s sum of squares, without its call overhead (the same bits)."""
    v = np.asarray(v, dtype=float)
    n = np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=True))
    return v / np.maximum(n, eps), n[..., 0]


def direction(v: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """``v / max(|v|, eps)`` along the last axis: :func:`unit` without the length."""
    return unit(v, eps)[0]
