"""The easing of the IK's contact handling.

:func:`smoothstep` is :math:`s(x) = 3x^2 - 2x^3` on :math:`x` clipped to :math:`[0, 1]`
(zero slope at both ends): the ramps of the height pulls, the hand-backs of the holds,
the eased contact weights and the heading follower's knee share all use it.
:func:`rounded_above` smooths a signal over time without ever going below it: the body's
drop for planted feet and the offset that takes a swing foot round the other leg.
"""

from __future__ import annotations

import numpy as np

__all__ = ["smoothstep", "rounded_above"]


def smoothstep(x):
    """:math:`x^2 (3 - 2x)` of ``x`` clipped to [0, 1]: a Python float for a scalar (no numpy
    overhead in the per-frame code), else an array."""
    if np.ndim(x) == 0:
        x = min(max(float(x), 0.0), 1.0)
        return x * x * (3.0 - 2.0 * x)
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def rounded_above(x: np.ndarray, n: int) -> np.ndarray:
    r""":math:`\bar{x}_t = \frac{1}{2n+1}\sum_{|s-t| \le n} \max_{|u-s| \le n} x_u` of ``x (F, ...)``
    over axis 0 (frames; the ends repeated): a moving average of the running maximum, each
    over :math:`2n + 1` frames.  Never below ``x`` (every window of the average holds a
    maximum over a window containing :math:`t`), no steeper than ``x``, and a one-frame
    turn of ``x`` is spread over :math:`2n + 1` frames.  ``x`` itself for :math:`n < 1`."""
    from scipy.ndimage import maximum_filter1d, uniform_filter1d

    x = np.asarray(x, dtype=float)
    if n < 1 or not x.size:
        return x
    size = 2 * int(n) + 1
    return uniform_filter1d(maximum_filter1d(x, size=size, axis=0, mode="nearest"), size=size, axis=0, mode="nearest")
