"""Ball joints written as hinges: their velocity limits bound the body's angular speed along
each hinge's axis, not the hinge rates that grow without bound at a gimbal lock."""

from __future__ import annotations

import mink
import mujoco
import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, retargeted, shared_file
from physmocap import metrics
from physmocap.ik.limits import GroupStepLimit, group_box_speeds
from physmocap.metrics.fidelity import saturation_matrix
from physmocap.models import load_character
from physmocap.models.hinge_groups import hinge_groups, joint_speeds

SHOULDER = ("right_shoulder_flexion", "right_shoulder_abduction", "right_shoulder_rotation")


def test_the_humanoids_three_hinge_joints_are_groups_and_a_robots_motors_are_not():
    ch = load_character("humanoid")
    groups = set(ch.velocity_groups)
    assert SHOULDER in groups and ("left_hip_flexion", "left_hip_adduction", "left_hip_rotation") in groups
    assert all(len(g) == 3 for g in groups)  # two hinges: the rates are the body's speeds already
    assert load_character("robot").velocity_groups == ()  # motor speeds: mapping-file limits
    # a hinge whose limit does not come from the human table breaks its group
    assert SHOULDER not in hinge_groups(ch.model, set(ch.velocity_limits) - {SHOULDER[1]})


def _locked(ch):
    """The rest pose with the right arm abducted 90 degrees (its rotation axis along the
    flexion axis: the gimbal lock), and the signed flexion/rotation pair that cancels there."""
    m = ch.model
    q = np.array(ch.rest_qpos, dtype=float)
    adr = [int(m.joint(n).qposadr[0]) for n in SHOULDER]
    q[adr[1]] = np.pi / 2
    data = mujoco.MjData(m)
    data.qpos[:] = q
    mujoco.mj_kinematics(m, data)
    a_flex, a_rot = (data.xaxis[m.joint(n).id] for n in (SHOULDER[0], SHOULDER[2]))
    assert abs(abs(a_flex @ a_rot) - 1.0) < 1e-9
    return q, adr, float(np.sign(a_flex @ a_rot))


def test_at_the_gimbal_lock_rates_that_cancel_are_no_turn_and_rates_that_add_are():
    ch = load_character("humanoid")
    q0, adr, sign = _locked(ch)
    fps, step = 120.0, 0.2  # 0.2 rad a frame = 24 rad/s: past the 26 rad/s flexion cap when doubled
    cancel, add = q0.copy(), q0.copy()
    cancel[adr[0]] += step
    cancel[adr[2]] -= sign * step
    add[adr[0]] += step
    add[adr[2]] += sign * step
    names = list(SHOULDER)
    for q, turn in ((cancel, 0.0), (add, 2 * step * fps)):
        raw = np.abs(q[adr] - q0[adr]) * fps
        grouped = joint_speeds(ch.model, np.stack([q0, q]), fps, names, [SHOULDER])[0]
        assert raw[0] == pytest.approx(step * fps)
        # along the flexion axis and the rotation axis (the same axis): the body's turn
        assert grouped[0] == pytest.approx(turn, abs=1e-6) and grouped[2] == pytest.approx(turn, abs=1e-6)
    # the solver's rows: from q0 (the previous frame), the cancelling step is allowed, the adding one is not
    limit = GroupStepLimit(ch.model, [SHOULDER], ch.velocity_limits, 1.0 / fps)
    limit.set_previous(q0)
    config = mink.Configuration(ch.model, q0)
    con = limit.compute_qp_inequalities(config, 1.0)
    for q, ok in ((cancel, True), (add, False)):
        dq = np.zeros(ch.model.nv)
        mujoco.mj_differentiatePos(ch.model, dq, 1.0, q0, q)
        assert bool(np.all(con.G @ dq <= con.h + 1e-12)) is ok
    # the box left on each hinge is its group's fastest limit
    box = group_box_speeds(ch.velocity_limits, [SHOULDER])
    assert box[SHOULDER[0]] == box[SHOULDER[1]] == box[SHOULDER[2]] == max(ch.velocity_limits[n] for n in SHOULDER)


def test_project_scales_a_group_step_back_inside_its_bound():
    ch = load_character("humanoid")
    q0, adr, sign = _locked(ch)
    fps = 120.0
    q = q0.copy()
    q[adr[0]] += 0.3
    q[adr[2]] += sign * 0.3  # adds: 72 rad/s along the axis
    limit = GroupStepLimit(ch.model, [SHOULDER], ch.velocity_limits, 1.0 / fps)
    limit.set_previous(q0)
    out = limit.project(ch.model, mujoco.MjData(ch.model), q)
    speed = joint_speeds(ch.model, np.stack([q0, out]), fps, list(SHOULDER), [SHOULDER])[0]
    caps = np.array([ch.velocity_limits[n] for n in SHOULDER])
    assert np.all(speed <= caps) and speed.max() > 0.99 * caps[0]  # as far as the bound allows
    d = (out - q0)[adr]
    assert d[0] == pytest.approx(sign * d[2]) and 0 < d[0] < 0.3  # the same step, scaled


@RETARGET_DIAGNOSTICS
def test_dance_shoulders_pass_their_gimbal_lock_without_sitting_at_a_cap():
    """The CMU dance raises the arms through the side (abduction past 90 degrees): the
    shoulder flexion rate sat at its 1500 deg/s cap on 7-10 frames per pass, which is no
    physical speed there.  Now no shoulder hinge's body speed reaches its cap, and none is
    over it (the trajectory's velocity-limit violations count the grouped speeds)."""
    shared_file("cmu_05_10_dance_spins.bvh")
    _, traj = retargeted("cmu_05_10_dance_spins.bvh", "humanoid")
    ch = traj.character
    names = list(ch.velocity_limits)
    sat = saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups)
    shoulders = [i for i, n in enumerate(names) if "shoulder" in n]
    assert not sat[:, shoulders].any()
    raw = saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits)
    assert raw[:, shoulders].any()  # the rates still swing fast through the lock
    vel = metrics.velocity_violations(ch.model, traj.qpos, traj.fps, ch.velocity_limits, groups=ch.velocity_groups)
    assert vel["count"] == 0
