"""Joints at their velocity caps eased offline (physmocap.ik.speedcaps; issue 9, "smoothness as
a guarantee": no joint at its velocity cap on more than 0.5 % of frames)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, retargeted, shared_file
from physmocap.ik.speedcaps import EASE_COST, FOLLOW_COST, TOUCH_SHARE, CapGuides, eased_reference, held_at_cap
from physmocap.metrics.fidelity import saturation_matrix, trajectory_fidelity

pytestmark = RETARGET_DIAGNOSTICS


def _ramp(F: int, start: int, frames: int, height: float) -> np.ndarray:
    """0 until ``start``, then up to ``height`` linearly over ``frames`` frames."""
    t = np.arange(F, dtype=float)
    return height * np.clip((t - start) / frames, 0.0, 1.0)


def _guides(ch, qpos: np.ndarray, fps: float) -> CapGuides:
    """The pass's guides for ``qpos``, from the report's own saturation matrix."""
    sat = saturation_matrix(ch.model, qpos, fps, ch.velocity_limits, ch.velocity_groups)
    return CapGuides(ch.model, qpos, fps, ch.velocity_limits, sat)


def test_a_move_too_fast_is_spread_out_centred_on_it():
    q = _ramp(200, 100, 4, 1.0)  # 0.25 a frame
    saturated = np.abs(np.diff(q)) > 0.2
    r = eased_reference(q, 0.05, saturated)
    assert np.abs(np.diff(r)).max() <= 0.05 + 1e-12
    assert np.all(np.diff(r) >= -1e-12)  # no overshoot: it only rises
    assert np.isclose(r[102], q[102])  # centred: half-way where the joint is half-way
    moved = np.flatnonzero(r != q)
    assert moved.min() < 100 and moved.max() > 104  # starts before the move, ends after it
    assert np.array_equal(r[:80], q[:80]) and np.array_equal(r[125:], q[125:])


def test_only_stretches_holding_a_saturated_transition_are_eased():
    q = _ramp(300, 50, 4, 1.0) + _ramp(300, 200, 4, 1.0)
    saturated = np.zeros(299, dtype=bool)
    saturated[201:203] = True  # the second move only
    r = eased_reference(q, 0.05, saturated)
    assert np.array_equal(r[:150], q[:150])
    assert not np.array_equal(r[150:], q[150:])
    assert np.array_equal(eased_reference(q, 0.05, np.zeros(299, dtype=bool)), q)


def test_a_clip_whose_joints_only_touch_their_caps_gets_no_pass():
    from physmocap.models import load_character

    one = np.zeros(199, dtype=bool)
    one[101] = one[103] = True  # twice, never running
    assert not held_at_cap(one).any()
    one[102] = True
    assert held_at_cap(one)[101:104].all()
    ch = load_character("robot")
    model = ch.model
    fps, F = 120.0, 240
    qpos = np.tile(ch.rest_qpos, (F, 1))
    joint = "l_elbow"
    adr = int(model.jnt_qposadr[model.joint(joint).id])
    qpos[:, adr] = _ramp(F, 120, 1, -ch.velocity_limits[joint] / fps)  # one transition at its cap
    assert int(saturation_matrix(model, qpos, fps, ch.velocity_limits, ch.velocity_groups).sum()) == 1
    touched = _guides(ch, qpos, fps)
    assert not touched.eased
    # touching it on more than TOUCH_SHARE of the transitions, one at a time, is a pass
    for start in (20, 60, 100, 140, 180):
        qpos[:, adr] += _ramp(F, start, 1, -ch.velocity_limits[joint] / fps)
    assert int(saturation_matrix(model, qpos, fps, ch.velocity_limits, ch.velocity_groups).sum()) == 6
    often = _guides(ch, qpos, fps)
    assert 6 / (F - 1) > TOUCH_SHARE and often.eased


def test_a_slow_joint_is_its_own_reference():
    q = np.sin(np.linspace(0.0, 6.0, 400))
    assert np.array_equal(eased_reference(q, 0.1, np.ones(399, dtype=bool)), q)


def test_guides_pull_the_saturated_joint_to_its_reference_and_the_rest_to_the_pass():
    from physmocap.models import load_character

    ch = load_character("robot")
    model = ch.model
    fps = 120.0
    F = 240
    qpos = np.tile(ch.rest_qpos, (F, 1))
    joint = "l_shoulder_pitch"
    adr = int(model.jnt_qposadr[model.joint(joint).id])
    vmax = ch.velocity_limits[joint]
    qpos[:, adr] = _ramp(F, 120, 6, -6.0 * vmax / fps)  # at its cap for six frames
    guides = _guides(ch, qpos, fps)
    assert guides.eased and len(guides) == F
    g = guides.get(118)
    k = int(np.flatnonzero(g.qpos == adr)[0])
    assert g.cost[k] == EASE_COST and np.all(np.delete(g.cost, k) == FOLLOW_COST)
    assert g.values[k] < qpos[118, adr]  # already on its way
    assert np.array_equal(np.delete(g.values, k), np.delete(qpos[118, g.qpos], k))
    assert g.follow and np.array_equal(g.start, qpos[118])
    far = guides.get(10)
    assert np.array_equal(far.values, qpos[10, far.qpos])
    still = _guides(ch, np.tile(ch.rest_qpos, (F, 1)), fps)
    assert not still.eased


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_no_joint_sits_at_its_velocity_cap_through_the_dance(character):
    """Before: on the CMU dance the robot's left shoulder pitch and yaw swung at their caps on
    12 % of the frames, turning opposite ways at the gimbal lock of the arm level at the side
    (any joint at its cap on 23.7 %); the humanoid's worst joint on 1.6 % (its right knee
    straightening where the source's thigh turns over, any joint 4.7 %)."""
    shared_file("cmu_05_10_dance_spins.bvh")
    _, traj = retargeted("cmu_05_10_dance_spins.bvh", character)
    fid = trajectory_fidelity(traj, floor_contact=False)
    assert fid.saturated_joint_share <= 0.005, (fid.saturated_joint, fid.saturated_joint_share)
    assert fid.saturated_share <= 0.02, fid.saturated_share  # single frames touching a cap are left
    assert fid.worst_segment_median_deg < 8.0  # the moves eased still follow the actor


def test_the_pass_can_be_switched_off():
    from physmocap.cli.retarget import config_from_args, retarget_option_parser

    p = retarget_option_parser()
    assert config_from_args(p.parse_args([])).solver.ease_caps is True
    assert config_from_args(p.parse_args(["--no-ease-caps"])).solver.ease_caps is False


def test_saturation_figure_matches_the_matrix_the_pass_reads():
    """The pass decides from the report's own figure (one definition of "at its cap")."""
    shared_file("cmu_05_10_dance_spins.bvh")
    _, traj = retargeted("cmu_05_10_dance_spins.bvh", "robot")
    ch = traj.character
    sat = saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups)
    fid = trajectory_fidelity(traj, floor_contact=False)
    assert np.isclose(fid.saturated_joint_share, sat.mean(axis=0).max())
