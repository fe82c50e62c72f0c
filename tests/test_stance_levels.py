"""A stream learns its contact points' stance levels as it goes (physmocap.ik.contacts.StanceLevels)
and stands its targets on them (StreamingRetargeter), instead of on the first frame's heights."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import RETARGET_DIAGNOSTICS, shared_file
from physmocap.ik.contacts import ContactOptions, StanceLevels

pytestmark = RETARGET_DIAGNOSTICS


def test_levels_start_where_they_are_given_and_wait_for_enough_slow_samples():
    opt = ContactOptions()
    lv = StanceLevels(np.array([0.10, 0.05]), 100.0, opt)
    need = math.ceil(StanceLevels.MIN_TIME * 100.0)
    for _ in range(need - 1):
        out = lv.update(np.array([0.06, 0.02]), np.zeros(2))
    assert np.array_equal(out, [0.10, 0.05])  # not enough yet
    out = lv.update(np.array([0.06, 0.02]), np.zeros(2))
    assert np.allclose(out, [0.06, 0.02], atol=StanceLevels.BIN)


def test_fast_samples_do_not_count_and_a_level_never_rises():
    opt = ContactOptions()
    lv = StanceLevels(np.array([0.05]), 50.0, opt)
    for _ in range(200):  # a swinging foot low and fast
        lv.update(np.array([-0.03]), np.array([opt.floor_speed * 2]))
    assert lv.levels[0] == 0.05
    for _ in range(200):  # standing higher than it started: the level stays
        lv.update(np.array([0.09]), np.zeros(1))
    assert lv.levels[0] == 0.05


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 0.2), st.floats(0.0, 0.05), st.integers(0, 2**31 - 1))
def test_the_level_is_the_percentile_of_the_slow_heights(stance, spread, seed):
    """Slow heights around a stance level, a few glitching far below: the level is their
    floor_percentile (as offline, estimate_floor), to the histogram's bin; the glitches
    (under the percentile's share) do not pull it down to them."""
    opt = ContactOptions()
    rng = np.random.default_rng(seed)
    heights = stance + spread * rng.random(400)
    heights[rng.choice(400, 8, replace=False)] = -0.2  # 2 % glitches
    lv = StanceLevels(np.array([1.0]), 120.0, opt)
    for h in heights:
        lv.update(np.array([h]), np.zeros(1))
    want = np.percentile(heights, opt.floor_percentile)
    assert abs(lv.levels[0] - want) <= 2 * StanceLevels.BIN + spread * 0.02
    assert lv.levels[0] > -0.1


def test_a_stream_stands_its_targets_on_the_learnt_ankle_height():
    """The OptiTrack actor's first frame has its ankles 4-5 cm above where they stand: the
    stream's ankle height comes down to the offline one within a centimetre, never
    faster than STANCE_LEVEL_SPEED of target height a second (back up by a bin or two at
    most, as the percentile settles), and its
    legs follow the actor more closely (worst leg segment median 10.5 degrees before)."""
    from physmocap.ik.retarget import retarget
    from physmocap.ik.stream import STANCE_LEVEL_SPEED, StreamingRetargeter
    from physmocap.metrics.fidelity import actor_joint_positions, character_joint_positions, segment_direction_errors
    from physmocap.models import load_character
    from physmocap.sources import load_motion
    from physmocap.trajectory import Trajectory

    motion = load_motion(shared_file("optitrack_hops_crouch.bvh")).slice_frames(0, 480)
    ch = load_character()
    stream = StreamingRetargeter(ch, skeleton=motion.skeleton, fps=motion.fps, translated=motion.translated)
    ankle, qpos = [], []
    for t in range(motion.num_frames):
        qpos.append(stream.step(rotations=motion.rotations[t], translations=motion.translations[t]))
        ankle.append(stream.calibration.ankle_actor)
    ankle = np.array(ankle)
    steps = np.diff(ankle)
    assert np.all(np.abs(steps) <= STANCE_LEVEL_SPEED / (motion.fps * stream.calibration.scale) + 1e-12)
    assert steps.max() <= 2 * StanceLevels.BIN  # the percentile moves by a bin or so as samples come
    offline = retarget(motion, ch, start=0, progress=False)
    assert ankle[0] - offline.targets.calibration.ankle_actor > 0.03  # the first frame's, too high
    assert abs(ankle[-1] - offline.targets.calibration.ankle_actor) < 0.01
    traj = Trajectory(ch, np.array(qpos), motion.fps)
    errors = segment_direction_errors(actor_joint_positions(motion, stream.joint_indices), character_joint_positions(traj))
    legs = [np.median(errors[s][120:]) for s in ("left_thigh", "right_thigh", "left_shank", "right_shank")]
    assert max(legs) < 7.0, legs
