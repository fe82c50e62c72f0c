"""The offline foot plan's helpers (physmocap.ik.footplan)."""

from __future__ import annotations

import numpy as np

from physmocap.ik.footplan import ease_weights, eased_mask


def test_eased_mask_ramps_outside_each_interval_and_takes_the_larger_of_two():
    mask = np.zeros(40, dtype=bool)
    mask[10:15] = True
    mask[20:24] = True
    w = eased_mask(mask, 3)
    assert np.all(w[mask] == 1.0) and w[0] == 0.0 and w[-1] == 0.0
    whole = np.maximum(ease_weights(40, 10, 14, 3), ease_weights(40, 20, 23, 3))
    assert np.array_equal(w, whole)
    assert np.array_equal(eased_mask(np.zeros(5, dtype=bool), 3), np.zeros(5))
