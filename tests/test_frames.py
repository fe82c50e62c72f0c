"""Segment frames from positions: orthonormal, right-handed, finite, with fallbacks."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from physmocap.frames import (
    chest_frame,
    frame_from_axes,
    head_frame,
    limb_frame,
    matrix_to_quat,
    pelvis_frame,
)
from physmocap.rotations import Rotation


def _assert_rotations(R: np.ndarray) -> None:
    assert np.all(np.isfinite(R))
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)


def test_pelvis_frame_axes_standing():
    R = pelvis_frame([0.0, 0.1, 1.0], [0.0, -0.1, 1.0], [0.0, 0.0, 1.3])
    _assert_rotations(R)
    np.testing.assert_allclose(R[:, 1], [0, 1, 0])  # y: left, exact
    np.testing.assert_allclose(R[:, 0], [1, 0, 0], atol=1e-12)  # x: forward
    # a spine leaning forward tilts z (and x) but never y
    R = pelvis_frame([0.0, 0.1, 1.0], [0.0, -0.1, 1.0], [0.1, 0.0, 1.3])
    np.testing.assert_allclose(R[:, 1], [0, 1, 0])
    assert R[0, 2] > 0 and R[2, 0] < 0
    # a pelvis turned 90 degrees to the left faces +y
    R = pelvis_frame([-0.1, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.0, 1.3])
    np.testing.assert_allclose(R[:, 0], [0, 1, 0], atol=1e-12)


def test_chest_and_head_frames():
    R = chest_frame([0, 0.2, 1.4], [0, -0.2, 1.4], [0, 0, 1.5], [0, 0, 1.1])
    _assert_rotations(R)
    np.testing.assert_allclose(R, np.eye(3), atol=1e-12)
    H = head_frame([0, 0, 1.5], [0.05, 0, 1.7], R[:, 1])
    _assert_rotations(H)
    np.testing.assert_allclose(H[:, 2], np.array([0.05, 0, 0.2]) / np.hypot(0.05, 0.2))


def test_limb_frame_bent_and_straight():
    hip, knee, ankle = np.array([0, 0, 1.0]), np.array([0.1, 0, 0.5]), np.array([0, 0, 0.0])
    R = limb_frame(hip, knee, ankle, fallback_axis=[0, -1, 0])
    _assert_rotations(R)
    np.testing.assert_allclose(R[:, 1], [0, -1, 0], atol=1e-12)  # knee hinge: body's right
    np.testing.assert_allclose(R[:, 2], (hip - knee) / np.linalg.norm(hip - knee))
    # straight leg: the fallback decides, no NaN
    S = limb_frame(hip, np.array([0, 0, 0.5]), ankle, fallback_axis=[0.3, -1, 0])
    _assert_rotations(S)
    np.testing.assert_allclose(S[:, 1], np.array([0.3, -1, 0]) / np.hypot(0.3, 1), atol=1e-12)
    D = limb_frame(hip, knee, ankle, fallback_axis=[0, -1, 0], distal=True)
    np.testing.assert_allclose(D[:, 2], (knee - ankle) / np.linalg.norm(knee - ankle))


def test_limb_frame_is_continuous_through_the_straight_region():
    """Straightening the knee step by step never flips the frame."""
    angles = np.radians(np.linspace(40, 0, 400))
    hip = np.array([0, 0, 1.0])
    knee = np.array([0, 0, 0.5])
    ankle = knee + 0.5 * np.stack([-np.sin(angles), 0 * angles, -np.cos(angles)], axis=-1)
    R = limb_frame(hip, knee, ankle, fallback_axis=[0, -1, 0])
    _assert_rotations(R)
    step = np.linalg.norm(np.diff(R, axis=0), axis=(1, 2))
    assert step.max() < 0.05


def test_degenerate_points_give_a_valid_frame():
    p = np.zeros(3)
    _assert_rotations(pelvis_frame(p, p, p))
    _assert_rotations(limb_frame(p, p, p, fallback_axis=[0, 0, 0]))
    _assert_rotations(frame_from_axes([0, 0, 1.0], [0, 0, 1.0]))


def test_matrix_to_quat_round_trip():
    q = Rotation.random(5, random_state=3).as_quat()
    R = Rotation.from_quat(q).as_matrix()
    q2 = matrix_to_quat(R.reshape(5, 3, 3))
    np.testing.assert_allclose(np.abs(np.sum(q * q2, axis=-1)), 1.0, atol=1e-12)


finite3 = hnp.arrays(float, (4, 3), elements=st.floats(-2, 2))


@settings(max_examples=50, deadline=None)
@given(finite3, finite3, finite3, hnp.arrays(float, (3,), elements=st.floats(-1, 1)))
def test_property_frames_always_orthonormal(a, b, c, f):
    _assert_rotations(limb_frame(a, b, c, fallback_axis=f))
    _assert_rotations(pelvis_frame(a, b, c))
    _assert_rotations(frame_from_axes(a - b, c, "zx"))
