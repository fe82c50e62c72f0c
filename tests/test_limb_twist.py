"""The upper arm's twist target comes from the actor's bent elbow (physmocap.ik.limbtwist),
not from how the source skeleton happens to orient its upper-arm frame."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS
from physmocap.ik.limbtwist import flexion_axis, twist_error
from physmocap.ik.retarget import retarget
from physmocap.ik.targets import build_targets
from physmocap.models import load_character
from physmocap.rotations import Rotation, quat_apply
from physmocap.sources import load_motion

pytestmark = RETARGET_DIAGNOSTICS


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_the_flexion_axis_is_signed_so_a_positive_turn_flexes(character):
    """The humanoid's elbow flexes with a positive angle, the robot's with a negative one:
    either way the axis found turns the forearm towards flexion (the larger side of the
    joint's range), in the upper arm's tracked frame."""
    import mujoco

    ch = load_character(character)
    model = ch.model
    for side in ("left", "right"):
        axes = flexion_axis(ch, f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")
        assert axes is not None and axes.signed and axes.twists
        h, u = axes.h, axes.u
        assert abs(float(h @ u)) < 0.2  # across the upper arm, not along it
        data = ch.rest_data()
        site = {k: ch.tracked[k] for k in (f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")}

        def pos(k):
            return data.site_xpos[model.site(site[k].name).id].copy()

        frame = data.site_xmat[model.site(site[f"{side}_shoulder"].name).id].reshape(3, 3).copy()
        # flex the hinge that swings the wrist most halfway into its larger side
        elbow_body = model.site_bodyid[model.site(site[f"{side}_elbow"].name).id]
        joints = [j for j in range(model.njnt) if model.jnt_bodyid[j] == elbow_body and model.jnt_type[j] == 3]
        lever = [np.linalg.norm(np.cross(data.xmat[elbow_body].reshape(3, 3) @ model.jnt_axis[j],
                                         pos(f"{side}_wrist") - data.xanchor[j])) for j in joints]
        j = joints[int(np.argmax(lever))]
        lo, hi = model.jnt_range[j]
        data.qpos[model.jnt_qposadr[j]] = 0.5 * (hi if hi + lo > 0 else lo)
        mujoco.mj_kinematics(model, data)
        upper = frame.T @ (pos(f"{side}_elbow") - pos(f"{side}_shoulder"))
        lower = frame.T @ (pos(f"{side}_wrist") - pos(f"{side}_elbow"))
        assert float(np.cross(upper, lower) @ h) > 0.0, (side, h)


@pytest.mark.parametrize("limited", [True, False])
def test_an_elbow_whose_range_does_not_tell_flexion_gets_the_same_targets(limited):
    """Before: the flexion axis took its sign from the elbow's range, so an elbow written
    the other way round with a symmetric range (or none: MJCF's default) turned the upper
    arm's twist target by 180 degrees and its forearm 10 degrees off (median).  The sign is
    now settled on the actor's bent elbow where the range does not tell."""
    motion = load_motion("example")
    ch = load_character("humanoid")
    joints = retarget(motion, ch, progress=False, start=0, end=2).joint_indices
    base = build_targets(motion, joints, ch)
    other = load_character("humanoid")
    model = other.model
    for j in range(model.njnt):
        if "elbow_flexion" in model.joint(j).name:
            model.jnt_axis[j] *= -1.0
            if limited:
                model.jnt_range[j] = [-2.8, 2.8]
            else:
                model.jnt_limited[j] = 0
    axes = flexion_axis(other, "left_shoulder", "left_elbow", "left_wrist")
    assert not axes.signed
    again = build_targets(motion, joints, other)
    for side in ("left", "right"):
        i = base.index(f"{side}_shoulder")
        dots = np.abs(np.sum(again.orientations[:, i] * base.orientations[:, i], axis=-1))
        assert dots.min() > 1.0 - 1e-9, side


def _retwisted(motion, joint: int, degrees: float):
    """The same motion with ``joint``'s frame turned by ``degrees`` about its bone (to its
    child): every world position and every other world rotation unchanged, as another
    vendor's skeleton might orient its upper arm."""
    sk = motion.skeleton
    children = [k for k in range(len(sk.names)) if sk.parents[k] == joint]
    bone = sk.offsets[children[0]] / np.linalg.norm(sk.offsets[children[0]])
    turn = Rotation.from_rotvec(np.radians(degrees) * bone)
    rot = motion.rotations.copy()
    rot[:, joint] = (Rotation.from_quat(rot[:, joint]) * turn).as_quat()
    offsets = sk.offsets.copy()
    for k in children:
        rot[:, k] = (turn.inv() * Rotation.from_quat(rot[:, k])).as_quat()
        offsets[k] = turn.inv().apply(offsets[k])
    skeleton = type(sk)(names=sk.names, parents=sk.parents, offsets=offsets, end_site=sk.end_site)
    import dataclasses

    return dataclasses.replace(motion, skeleton=skeleton, rotations=rot)


def test_the_upper_arm_target_does_not_depend_on_the_source_frame_twist():
    """Before: the upper arm had no orientation target; its twist was whatever the wrist
    target left (an arm hanging straight in a walk wandered; on the CMU dance the IK kept
    a hyperextended elbow and turned its backward bend towards the hand).  Calibrated
    from the rest poses alone its twist was 30 degrees off CMU's elbow plane, and would
    follow any vendor's choice of upper-arm frame.  Now it is calibrated on the actor's
    bent elbow: the same targets whichever way the source orients the upper arm."""
    motion = load_motion("example")
    ch = load_character("humanoid")
    joints = retarget(motion, ch, progress=False, start=0, end=2).joint_indices
    base = build_targets(motion, joints, ch)
    for side in ("left", "right"):
        i = base.index(f"{side}_shoulder")
        assert base.has_orientation[i]
        e, w = base.index(f"{side}_elbow"), base.index(f"{side}_wrist")
        S = base.source_positions
        axes = flexion_axis(ch, f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")
        phi, bend = twist_error(base.orientations[:, i], axes, S[:, e] - S[:, i], S[:, w] - S[:, e])
        bent = bend > np.radians(20.0)
        assert bent.sum() > 50
        assert np.degrees(np.abs(phi[bent])).max() < 1.0  # CMU's elbow is a hinge: exact
        for degrees in (70.0, -130.0):
            other = build_targets(_retwisted(motion, joints[f"{side}_shoulder"], degrees), joints, ch)
            np.testing.assert_allclose(other.positions, base.positions, atol=1e-9)
            # the same orientation (quaternion sign aside)
            dots = np.abs(np.sum(other.orientations[:, i] * base.orientations[:, i], axis=-1))
            assert dots.min() > 1.0 - 1e-9, degrees
            # the predicted flexion axis lies in the actor's elbow plane
            h = quat_apply(other.orientations[bent, i], axes.h)
            n = np.cross(S[bent, e] - S[bent, i], S[bent, w] - S[bent, e])
            cos = np.sum(h * n, axis=-1) / np.linalg.norm(n, axis=-1)
            assert cos.min() > np.cos(np.radians(1.0))


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_raised_arms_do_not_stay_on_a_branch_that_cannot_reach_the_actor(character):
    """Before: on the CMU dance the humanoid's right arm went up by abduction with its
    shoulder rotation at the limit, and when the actor bent the elbow behind the head it
    stayed straight up (forearms more than 45 degrees off on 5.3 % of the frames, 518-560);
    the robot's arms went overhead by roll and stayed at the roll and yaw limits (23.3 % of
    the frames), although within every range a pose matched the actor's to millimetres.
    A second pass guides them onto the branch that reaches (physmocap.ik.branches).  Since
    stop 37 the robot's right upper arm is more than 45 degrees off on 5 frames (504-508, a
    0.15 s excursion from 496 to 514 peaking at 48 degrees: README, Known limits), so the
    robot's arms are held to the issue's 1 %, the humanoid's to 0.5 %."""
    from conftest import retargeted, shared_file

    from physmocap.metrics.fidelity import trajectory_fidelity

    shared_file("cmu_05_10_dance_spins.bvh")
    _, traj = retargeted("cmu_05_10_dance_spins.bvh", character)
    fid = trajectory_fidelity(traj, floor_contact=False)
    arms = ("left_upper_arm", "right_upper_arm", "left_forearm", "right_forearm")
    bound = 0.005 if character == "humanoid" else 0.01
    assert max(fid.segments[s].share_over_45 for s in arms) < bound, {s: fid.segments[s].share_over_45 for s in arms}
    assert fid.share_any_over_45 < 0.01


@pytest.mark.parametrize("clip", ["cmu_12_01_walk.bvh", "bandai_punch.bvh"])
def test_no_second_pass_where_every_arm_follows(clip):
    """An arm that follows the actor (a walk; a boxing guard held all clip) is never taken
    for a stuck one: no guide, the first pass's output stands."""
    from conftest import retargeted

    from physmocap.ik.branches import plan_guides
    from physmocap.ik.retarget import _arm_errors

    _, traj = retargeted(clip, "humanoid")
    assert plan_guides(traj, _arm_errors(traj)) == {}


def test_the_second_pass_can_be_turned_off_from_the_command_line():
    from physmocap.cli.retarget import config_from_args, retarget_option_parser

    p = retarget_option_parser()
    assert config_from_args(p.parse_args([])).solver.arm_branches is True
    assert config_from_args(p.parse_args(["--no-arm-branches"])).solver.arm_branches is False


def test_an_orientation_asked_of_a_frame_that_cannot_twist_is_said_to_be_dropped():
    """The G1's hip frames are its roll links, the thigh's yaw below them: asked for (the
    default asks for none), their orientation targets are dropped with one warning each,
    not silently."""
    from conftest import shared_file

    from physmocap.ik.targets import ORIENTED

    g1 = shared_file("../robots/unitree_g1/g1_mocap_29dof.xml")
    ch = load_character(g1)
    with pytest.warns(UserWarning, match=r"no orientation target for (left|right)_hip"):
        retarget(load_motion("example"), ch, progress=False, end=10, oriented=ORIENTED + ("left_hip", "right_hip"))


def test_a_stream_learns_the_twist_as_it_goes():
    """Before: a stream calibrated the upper arm's twist on its first frame alone; with the
    elbow straight there (a T-pose, or the Bandai walk's 14.5 degrees) it kept the rest
    poses' twist, 30 degrees off CMU's elbow plane (32.5 on the Bandai walk), for good.  Now
    the calibration keeps learning from every bent frame the stream sees
    (limbtwist.TwistCalibration): the same targets as offline once the elbow has bent."""
    from physmocap.ik.retarget import map_motion

    motion = load_motion("example").slice_frames(0, 241)  # frame 0: CMU's T-pose, elbows straight
    ch = load_character("humanoid")
    joints = map_motion(motion)
    offline = build_targets(motion, joints, ch)
    cal = build_targets(motion.slice_frames(0, 1), joints, ch).calibration
    cal.restart_twists()  # as a stream does: the first frame is given again below
    frames = [build_targets(motion.slice_frames(t, t + 1), joints, ch, calibration=cal) for t in range(motion.num_frames)]
    for side in ("left", "right"):
        i = offline.index(f"{side}_shoulder")
        streamed = np.array([f.orientations[0, i] for f in frames])
        dots = np.abs(np.sum(streamed[120:] * offline.orientations[120:, i], axis=-1))
        assert dots.min() > np.cos(np.radians(0.5) / 2), side  # within half a degree


def test_a_source_without_arms_retargets_in_one_pass():
    """Before: with no arm on the source (a legs-and-trunk skeleton), looking for stuck arms
    stacked an empty list of arm errors and failed."""
    from physmocap.ik.retarget import map_motion

    motion = load_motion("example").slice_frames(1, 31)
    joints = {c: j for c, j in map_motion(motion).items()
              if not any(k in c for k in ("clavicle", "shoulder", "elbow", "wrist", "hand"))}
    traj = retarget(motion, load_character("humanoid"), progress=False, joint_indices=joints)
    assert np.isfinite(traj.qpos).all()
