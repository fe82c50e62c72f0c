"""The pelvis gives way where the actor's trunk leans further over it than the character's
torso joints reach (physmocap.ik.trunkreach)."""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from conftest import RETARGET_DIAGNOSTICS, retargeted, shared_file
from physmocap.ik.trunkreach import TOLERANCE_DEG, TrunkReach, trunk_reach
from physmocap.metrics.fidelity import trajectory_fidelity
from physmocap.models import load_character

pytestmark = RETARGET_DIAGNOSTICS

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def _pitch(d: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(d[..., 0], d[..., 2]))


def test_a_trunk_within_reach_leaves_the_pelvis_alone_and_one_beyond_turns_it_by_the_excess():
    reach = TrunkReach(Rotation.from_euler("y", np.linspace(-10, 20, 121)[:, None], degrees=True).apply([0, 0, 1.0]),
                       np.array([0.0, 1.0, 0.0]), IDENTITY)
    pelvis = Rotation.from_euler("y", [[0.0], [30.0], [5.0]], degrees=True).as_quat()
    trunk = Rotation.from_euler("y", [[-30.0], [0.0], [10.0]], degrees=True).apply([0, 0, 1.0])
    out = reach.give_way(pelvis, trunk)
    np.testing.assert_allclose(out[2], pelvis[2])  # 5 degrees over the pelvis: within reach
    local = Rotation.from_quat(out).inv().apply(trunk)
    # 30 degrees back over the pelvis (the reach: 10): the pelvis turns back by 20 less the tolerance
    assert abs(_pitch(local[0]) - (-10.0 - TOLERANCE_DEG)) < 0.05
    assert abs(_pitch(local[1]) - (-10.0 - TOLERANCE_DEG)) < 0.05
    turned = np.degrees((Rotation.from_quat(out[:2]) * Rotation.from_quat(pelvis[:2]).inv()).magnitude())
    np.testing.assert_allclose(turned, 20.0 - TOLERANCE_DEG, atol=0.05)
    # a lost trunk (not finite) leaves its frame alone
    lost = reach.give_way(pelvis[:1], np.full((1, 3), np.nan))
    np.testing.assert_allclose(lost, pelvis[:1])
    # and so does a lost pelvis, without failing the frames around it
    gap = np.vstack([pelvis[:1], np.full((1, 4), np.nan), pelvis[1:2]])
    kept = reach.give_way(gap, trunk[[0, 0, 1]])
    assert np.all(np.isnan(kept[1])) and np.allclose(kept[[0, 2]], out[:2])


def test_a_stream_s_turns_are_averaged_over_its_last_frames():
    """Frame by frame with a history, each frame's turn is the mean of its own (what
    give_way alone gives it) and those of the frames before, at most ``window`` of them:
    a trunk that steps beyond reach and back moves the pelvis in steps a window long, not at
    once (the streamed dance robot's pelvis target stepped 2-4 degrees in a frame)."""
    from collections import deque

    reach = TrunkReach(Rotation.from_euler("y", np.linspace(-10, 20, 121)[:, None], degrees=True).apply([0, 0, 1.0]),
                       np.array([0.0, 1.0, 0.0]), IDENTITY)
    leans = [0, 0, -30, -30, -30, -30, 0, 0, 0, -20]
    window = 3
    history = deque(maxlen=window)
    raw, averaged = [], []
    for lean in leans:
        trunk = Rotation.from_euler("y", [[lean]], degrees=True).apply([0, 0, 1.0])
        alone = reach.give_way(IDENTITY[None], trunk)
        raw.append(Rotation.from_quat(alone).as_rotvec()[0])
        averaged.append(Rotation.from_quat(reach.give_way(IDENTITY[None], trunk, window, history)).as_rotvec()[0])
    raw, averaged = np.array(raw), np.array(averaged)
    for t in range(len(leans)):
        np.testing.assert_allclose(averaged[t], raw[max(0, t - window + 1) : t + 1].mean(axis=0), atol=1e-12)
    steps = np.degrees(np.linalg.norm(np.diff(averaged, axis=0), axis=1))
    assert steps.max() <= np.degrees(np.linalg.norm(raw, axis=1)).max() / window + 1e-9


def test_the_robot_s_reach_is_its_waist_s_and_the_same_every_time():
    ch = load_character("robot")
    reach = trunk_reach(ch)
    assert reach is not None and reach.directions.shape[1] == 3
    np.testing.assert_allclose(np.linalg.norm(reach.directions, axis=1), 1.0)
    np.testing.assert_array_equal(reach.directions, trunk_reach(ch).directions)
    model, data = ch.model, ch.rest_data()
    pitch_adr = model.joint("waist_pitch").qposadr[0]

    def trunk_at(waist_pitch: float) -> np.ndarray:
        data.qpos[pitch_adr] = waist_pitch
        mujoco.mj_kinematics(model, data)
        d = ch.tracked["neck"].position(model, data) - ch.tracked["pelvis"].position(model, data)
        return data.xmat[ch.tracked["pelvis"].body_id(model)].reshape(3, 3).T @ d

    lo, hi = model.jnt_range[model.joint("waist_pitch").id]
    back, front = _pitch(trunk_at(lo)), _pitch(trunk_at(hi))
    pitches = _pitch(reach.directions)
    assert pitches.min() >= back - 0.5 and pitches.max() <= front + 0.5  # nothing beyond the waist's range
    assert pitches.min() < back + 1.0 and pitches.max() > front - 1.0  # and the range's ends are sampled
    upright = np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(np.max(reach.directions @ upright))) < TOLERANCE_DEG  # standing straight is reached


def test_the_dance_robot_s_pelvis_gives_way_where_its_waist_cannot_follow():
    """Before: the CMU dance's actor tilts its pelvis some 24 degrees forward under an upright
    spine; the robot's waist, which extends 20, sat at that limit on 73 % of the frames, the
    pelvis held where the actor's is, and the robot's trunk was 5.9 degrees off, its right upper
    arm 8.2.  The waist still works at its limit (the trunk sits at the edge of its reach);
    the pelvis now tips back to make up the rest."""
    shared_file("cmu_05_10_dance_spins.bvh")
    _, traj = retargeted("cmu_05_10_dance_spins.bvh", "robot")
    fid = trajectory_fidelity(traj)
    assert fid.segments["torso"].median_deg < 4.5 and fid.segments["right_upper_arm"].median_deg < 6.0
    assert fid.facing_p95_deg < 10.0  # tipped about its hip line, the pelvis keeps its heading


def test_reach_is_measured_once_per_character_and_a_copy_starts_afresh():
    """The reach is kept on the character (a stream measures it before its first frame), the
    same object every call; a character copied with ``dataclasses.replace`` measures its own."""
    import dataclasses

    from physmocap.ik.stream import StreamingRetargeter
    from physmocap.resources import example_clip
    from physmocap.sources import load_motion

    ch = load_character("humanoid")
    m = load_motion(example_clip())
    StreamingRetargeter(ch, skeleton=m.skeleton, fps=m.fps, translated=m.translated)
    kept = ch._derived[("trunk_reach", 4096)]
    assert kept is not None and trunk_reach(ch) is kept
    copy = dataclasses.replace(ch)
    assert not copy._derived
    again = trunk_reach(copy)
    assert again is not kept and np.array_equal(again.directions, kept.directions)
