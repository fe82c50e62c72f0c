"""The one easing curve of the IK's contact handling.

:func:`smoothstep` is :math:`s(x) = 3x^2 - 2x^3` on :math:`x` clipped to :math:`[0, 1]`
(zero slope at both ends): the ramps of the height pulls, the hand-backs of the holds,
the eased contact weights and the heading follower's knee share all use it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["smoothstep"]


def smoothstep(x):
    """:math:`x^2 (3 - 2x)` of ``x`` clipped to [0, 1]: a Python float for a scalar (no numpy
    overhead in the per-frame code), else an array."""
    if np.ndim(x) == 0:
        x = min(max(float(x), 0.0), 1.0)
        return x * x * (3.0 - 2.0 * x)
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)
