"""Slip and scuffing of collision geoms (physmocap.metrics.fidelity.geom_floor_contact):
a foot turning about a point it stands on pivots, a foot whose every point moves slides."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physmocap.metrics.fidelity import geom_floor_contact, pivot_slip

#: Two free "feet": a box 20 x 10 cm (2 cm thick) and, on a second body, a sphere.
XML = """
<mujoco>
  <worldbody>
    <body name="foot" pos="0 0 0.01">
      <freejoint/>
      <geom name="sole" type="box" size="0.1 0.05 0.01"/>
    </body>
    <body name="other" pos="0 1 0.5">
      <freejoint/>
      <geom name="ball" type="sphere" size="0.02"/>
    </body>
  </worldbody>
</mujoco>
"""

FPS = 100.0


def _model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(XML)


def _trajectory(foot_xy_yaw: np.ndarray, other_xyz: np.ndarray) -> np.ndarray:
    """qpos (F, 14): the box at (x, y, 1 cm up) turned by yaw, the sphere at (x, y, z)."""
    F = len(foot_xy_yaw)
    q = np.zeros((F, 14))
    q[:, 0:2] = foot_xy_yaw[:, :2]
    q[:, 2] = 0.01
    q[:, 3] = np.cos(foot_xy_yaw[:, 2] / 2)
    q[:, 6] = np.sin(foot_xy_yaw[:, 2] / 2)
    q[:, 7:10] = other_xyz
    q[:, 10] = 1.0
    return q


def _pivot_about(point: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(F, 3) box centre and yaw turning about ``point`` (world xy) from yaw 0."""
    c, s = np.cos(angles), np.sin(angles)
    centre = point[None] + np.stack([c * -point[0] - s * -point[1], s * -point[0] + c * -point[1]], axis=1)
    return np.column_stack([centre, angles])


def test_pivot_slip_is_zero_about_a_point_of_the_patch_and_the_shift_otherwise():
    square = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1]])
    th = 0.1
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    pivot = np.array([0.2, 0.05])  # the middle of the front edge
    turned = (square - pivot) @ R.T + pivot
    assert pivot_slip(square, turned) == pytest.approx(0.0, abs=1e-12)
    assert pivot_slip(square, square + [0.03, -0.04]) == pytest.approx(0.05)
    # turning about a point 10 cm in front of the patch: the front edge moves by 2 sin(th/2) 10 cm
    outside = np.array([0.3, 0.05])
    turned = (square - outside) @ R.T + outside
    assert pivot_slip(square, turned) == pytest.approx(2 * np.sin(th / 2) * 0.1, rel=1e-9)
    # a single point and a segment (two points of a capsule) work too
    assert pivot_slip(square[:1], square[:1] + [0.0, 0.02]) == pytest.approx(0.02)
    seg = square[:2]
    assert pivot_slip(seg, (seg - seg[1]) @ R.T + seg[1]) == pytest.approx(0.0, abs=1e-12)


def test_a_foot_pivoting_on_the_floor_does_not_slip_but_its_geom_slides():
    model = _model()
    body = model.body("foot").id
    F = 30
    # turning 90 degrees/s about the middle of the box's front edge (10 cm ahead of its centre)
    foot = _pivot_about(np.array([0.1, 0.0]), np.radians(90.0) * np.arange(F) / FPS)
    q = _trajectory(foot, np.tile([0.0, 1.0, 0.5], (F, 1)))
    fc = geom_floor_contact(model, q, FPS, feet={"foot": [body]})
    assert fc.resting_samples == F - 1
    assert fc.slip_mean_cm_s == pytest.approx(0.0, abs=1e-6)
    # the bottom face's centre swings round at 10 cm x pi/2 rad/s
    assert fc.geom_slip_mean_cm_s == pytest.approx(100 * 0.1 * np.pi / 2, rel=1e-3)


def test_a_foot_sliding_slips_as_fast_as_it_slides():
    model = _model()
    F = 30
    foot = np.column_stack([0.2 * np.arange(F) / FPS, np.zeros(F), np.zeros(F)])  # 20 cm/s
    q = _trajectory(foot, np.tile([0.0, 1.0, 0.5], (F, 1)))
    fc = geom_floor_contact(model, q, FPS, feet={"foot": [model.body("foot").id]})
    assert fc.slip_mean_cm_s == pytest.approx(20.0, rel=1e-6)
    assert fc.geom_slip_mean_cm_s == pytest.approx(20.0, rel=1e-6)


def test_a_swing_foot_skimming_the_floor_scuffs_and_a_planted_one_does_not():
    model = _model()
    F = 20
    still = np.zeros((F, 3))
    # the sphere skims 5 mm above the floor at 1 m/s: every near-floor transition of it scuffs
    skim = np.column_stack([np.arange(F) / FPS, np.ones(F), np.full(F, 0.025)])
    q = _trajectory(still, skim)
    feet = {"foot": [model.body("foot").id], "other": [model.body("other").id]}
    fc = geom_floor_contact(model, q, FPS, feet=feet)
    assert fc.near_samples == 2 * (F - 1)  # the resting box and the skimming sphere
    assert fc.scuff_share == pytest.approx(0.5)
    # the same sphere as part of the resting foot: it moves with a planted foot, not a swing foot
    fc = geom_floor_contact(model, q, FPS, feet={"foot": [model.body("foot").id, model.body("other").id]})
    assert fc.scuff_share == 0.0
