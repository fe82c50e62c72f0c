"""One Euro filter: causality, smoothing, lag, gaps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physmocap.filters import OneEuroFilter, one_euro_filter, smoothing_alpha


def test_alpha_matches_the_paper_formula():
    dt, fc = 1 / 30, 2.0
    tau = 1 / (2 * np.pi * fc)
    assert smoothing_alpha(fc, dt) == pytest.approx(1 / (1 + tau / dt))


def test_constant_signal_passes_unchanged():
    x = np.tile([[0.1, 0.2, 0.3]], (50, 4, 1))
    y = one_euro_filter(x, fps=30)
    np.testing.assert_allclose(y, x, atol=1e-15)


def test_reduces_jitter_at_rest_and_keeps_up_when_moving():
    rng = np.random.default_rng(0)
    fps = 30.0
    t = np.arange(300) / fps
    truth = np.zeros((300, 1, 3))
    truth[150:, 0, 0] = 1.5 * (t[150:] - t[150])  # start walking at 1.5 m/s
    noisy = truth + rng.normal(0, 0.01, truth.shape)
    y = one_euro_filter(noisy, fps=fps, min_cutoff=1.0, beta=2.0)
    rest_err_raw = np.abs(noisy[20:150] - truth[20:150]).std()
    rest_err = np.abs(y[20:150] - truth[20:150]).std()
    assert rest_err < 0.4 * rest_err_raw
    # lag while moving stays small: under 4 cm at 1.5 m/s
    lag = np.abs(y[200:, 0, 0] - truth[200:, 0, 0]).mean()
    assert lag < 0.04


def test_causal_step_equals_batch():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(40, 3, 3))
    y = one_euro_filter(x, fps=60, beta=0.7)
    f = OneEuroFilter(beta=0.7)
    for i in range(40):
        np.testing.assert_allclose(f.step(x[i], i / 60), y[i])
    # the output of frame i does not depend on later frames
    x2 = x.copy()
    x2[25:] += 5.0
    y2 = one_euro_filter(x2, fps=60, beta=0.7)
    np.testing.assert_array_equal(y2[:25], y[:25])


def test_invalid_samples_hold_and_restart():
    x = np.zeros((10, 2, 3))
    x[:, 1] = 1.0
    x[6:, 0] = 3.0  # joint 0 re-acquired elsewhere after a gap
    valid = np.ones((10, 2), dtype=bool)
    valid[3:6, 0] = False
    x[3:6, 0] = np.nan
    y = one_euro_filter(x, fps=30, valid=valid)
    assert np.all(np.isfinite(y))
    np.testing.assert_array_equal(y[3:6, 0], 0.0)  # held last estimate
    np.testing.assert_array_equal(y[6:, 0], 3.0)  # restarted, no glide


def test_repeated_timestamp_returns_previous_estimate():
    f = OneEuroFilter()
    a = f.step(np.array([0.0, 0.0, 0.0]), 0.0)
    b = f.step(np.array([1.0, 0.0, 0.0]), 0.0)
    np.testing.assert_array_equal(a, b)


def test_bad_parameters():
    with pytest.raises(ValueError):
        OneEuroFilter(min_cutoff=0)
    with pytest.raises(ValueError):
        OneEuroFilter(beta=-1)
    with pytest.raises(ValueError):
        one_euro_filter(np.zeros((3, 3)))


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.floats(-10, 10), min_size=2, max_size=30),
    st.floats(0.1, 10),
    st.floats(0, 5),
)
def test_output_stays_within_input_range_for_scalars(xs, min_cutoff, beta):
    """A first-order low-pass with alpha in (0, 1] never overshoots its input's range."""
    x = np.array(xs)
    y = one_euro_filter(x, fps=30, min_cutoff=min_cutoff, beta=beta, vector_axis=None)
    assert np.all(y >= x.min() - 1e-9) and np.all(y <= x.max() + 1e-9)
