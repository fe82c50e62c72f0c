"""Vectors along the last axis of an array: the one place unit vectors are made.

Every module that normalises directions (segments, limb planes, foot lines) calls
:func:`unit`; what a near-zero vector becomes is the caller's choice (``eps``, or a
fallback where the length is below it).  Lengths in the input's units (metres inside).
"""

from __future__ import annotations

import numpy as np

__all__ = ["unit"]


def unit(v: np.ndarray, eps: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    r"""``(u, n)``: :math:`u = v / \max(\lVert v\rVert, \varepsilon)` and :math:`n = \lVert v\rVert`
    along the last axis (``u`` shaped as ``v``, ``n`` without its last axis).  A vector shorter
    than ``eps`` comes out shorter than one (no division by zero); test ``n`` to tell.  The
    length is ``np.linalg.norm``'s sum of squares, without its call overhead (the same bits)."""
    n = np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=True))
    return v / np.maximum(n, eps), n[..., 0]
