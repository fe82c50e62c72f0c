"""Gap policy: short gaps filled, long ones masked, lost frames held, nothing non-finite."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from physmocap.sources.gaps import fill_gaps, find_runs

NAMES = ("a", "b", "c")


def _ramp(F: int = 20, J: int = 3) -> np.ndarray:
    t = np.arange(F, dtype=float)
    return np.stack([np.stack([t + j, 2 * t, -t], axis=-1) for j in range(J)], axis=1)


def test_find_runs():
    assert find_runs(np.array([0, 1, 1, 0, 1], dtype=bool)) == [(1, 2), (4, 4)]
    assert find_runs(np.zeros(0, dtype=bool)) == []
    assert find_runs(np.ones(3, dtype=bool)) == [(0, 2)]


def test_short_interior_gap_is_interpolated():
    x = _ramp()
    y = x.copy()
    y[5:8, 1] = np.nan
    r = fill_gaps(y, None, NAMES, max_gap_frames=3)
    np.testing.assert_allclose(r.positions, x)  # linear data: exact
    assert r.valid.all()
    assert r.gaps == [{"joint": "b", "start": 5, "end": 7, "frames": 3, "action": "filled"}]


def test_long_gap_is_masked_and_held():
    x = _ramp()
    y = x.copy()
    y[5:12, 0] = np.nan
    r = fill_gaps(y, None, NAMES, max_gap_frames=3)
    assert not r.valid[5:12, 0].any() and r.valid[12:, 0].all()
    np.testing.assert_array_equal(r.positions[5:12, 0], np.broadcast_to(x[4, 0], (7, 3)))
    assert r.gaps[0]["action"] == "masked"


def test_low_confidence_counts_as_missing_and_edges_are_masked():
    x = _ramp()
    conf = np.ones(x.shape[:2])
    conf[:2, 2] = 0.2  # start of the clip: cannot interpolate
    conf[-1, 1] = 0.0  # end of the clip
    r = fill_gaps(x, conf, NAMES, max_gap_frames=5, min_confidence=0.5)
    assert (r.confidence[:2, 2] == 0).all() and (r.confidence[-1, 1] == 0)
    np.testing.assert_array_equal(r.positions[:2, 2], np.broadcast_to(x[2, 2], (2, 3)))
    np.testing.assert_array_equal(r.positions[-1, 1], x[-2, 1])
    assert {g["action"] for g in r.gaps} == {"masked"}


def test_lost_frames_hold_the_last_pose():
    x = _ramp(30)
    y = x.copy()
    y[10:20] = np.nan  # tracker lost everything for 10 frames
    conf = np.full(x.shape[:2], 0.9)
    r = fill_gaps(y, conf, NAMES, max_gap_frames=4)
    np.testing.assert_array_equal(r.positions[10:20], np.broadcast_to(x[9], (10, 3, 3)))
    np.testing.assert_array_equal(r.confidence[10:20], 0.9)  # whole pose held, tasks on
    assert r.lost[10:20].all() and r.lost.sum() == 10
    assert r.gaps == [{"joint": "*", "start": 10, "end": 19, "frames": 10, "action": "held"}]


def test_short_lost_run_is_interpolated():
    x = _ramp(30)
    y = x.copy()
    y[10:12] = np.nan
    r = fill_gaps(y, None, NAMES, max_gap_frames=4)
    np.testing.assert_allclose(r.positions, x)
    assert r.gaps == [{"joint": "*", "start": 10, "end": 11, "frames": 2, "action": "filled"}]


def test_never_seen_joint_sits_on_its_parent():
    x = _ramp()
    x[:, 2] = np.nan
    r = fill_gaps(x, None, NAMES, max_gap_frames=3, parents=np.array([-1, 0, 1]))
    np.testing.assert_array_equal(r.positions[:, 2], r.positions[:, 1])
    assert not r.valid[:, 2].any()
    assert r.gaps == [{"joint": "c", "start": 0, "end": 19, "frames": 20, "action": "masked"}]
    json.dumps(r.gaps)  # serialisable for the report


@settings(max_examples=40, deadline=None)
@given(
    hnp.arrays(bool, st.tuples(st.integers(1, 25), st.integers(1, 4))),
    st.integers(0, 6),
    st.integers(0, 2**31 - 1),
)
def test_property_always_finite_and_valid_samples_untouched(missing, max_gap, seed):
    F, J = missing.shape
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(F, J, 3))
    y = np.where(missing[..., None], np.nan, x)
    r = fill_gaps(y, None, [f"j{k}" for k in range(J)], max_gap_frames=max_gap)
    assert np.all(np.isfinite(r.positions)) and np.all(np.isfinite(r.confidence))
    assert np.all((r.confidence >= 0) & (r.confidence <= 1))
    np.testing.assert_array_equal(r.positions[~missing], x[~missing])
    assert r.valid[~missing].all()
    # every missing sample is covered by exactly the gap records' frames
    covered = np.zeros_like(missing)
    names = [f"j{k}" for k in range(J)]
    for g in r.gaps:
        cols = range(J) if g["joint"] == "*" else [names.index(g["joint"])]
        for c in cols:
            covered[g["start"] : g["end"] + 1, c] = True
    assert np.all(covered[missing])


def test_rejects_negative_span():
    with pytest.raises(ValueError):
        fill_gaps(_ramp(), None, NAMES, max_gap_frames=-1)


def test_causal_filler_holds_masks_and_holds_lost_frames():
    from physmocap.sources.gaps import CausalGapFiller

    x = _ramp(10)
    y = x.copy()
    y[3, 1] = np.nan  # one joint lost
    y[6] = np.nan  # whole frame lost
    y[:2, 2] = np.nan  # not seen yet: sits on its parent
    conf = np.full((10, 3), 0.8)
    f = CausalGapFiller(3, parents=np.array([-1, 0, 1]))
    out = [f.step(y[i], conf[i]) for i in range(10)]
    P = np.array([o[0] for o in out])
    C = np.array([o[1] for o in out])
    assert np.all(np.isfinite(P))
    np.testing.assert_array_equal(P[3, 1], x[2, 1])
    assert C[3, 1] == 0.0 and C[4, 1] == 0.8
    np.testing.assert_array_equal(P[6], P[5])
    np.testing.assert_array_equal(C[6], C[5])
    np.testing.assert_array_equal(P[:2, 2], P[:2, 1])
    assert (C[:2, 2] == 0).all() and f.lost_frames == 1
    # without gaps it is the identity, like the batch policy
    g = CausalGapFiller(3)
    for i in range(10):
        p, c = g.step(x[i])
        np.testing.assert_array_equal(p, x[i])
        assert (c == 1).all()
