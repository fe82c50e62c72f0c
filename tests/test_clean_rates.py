"""Detection at any frame rate (issue 12): the jump out of CMU's reference T-pose is no
glitch whether the clip is resampled to 24 Hz (one frame, among large real steps) or to 240 Hz
(spread over two frames)."""

from __future__ import annotations

import warnings

import pytest

from conftest import shared_file
from physmocap.clean import CleanOptions, clean
from physmocap.clean.detect import reference_exit
from physmocap.sources import load_motion


def _load(name: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_motion(shared_file(name))


@pytest.mark.parametrize("clip", ["cmu_12_01_walk.bvh", "cmu_01_01_jumps.bvh"])
@pytest.mark.parametrize("fps", [24.0, 240.0])
def test_resampled_cmu_clip_has_no_glitch_at_its_reference_pose(clip, fps):
    m = _load(clip)
    if clip == "cmu_01_01_jumps.bvh":
        m = m.slice_frames(0, 600)  # the start is what matters; 5 s keeps it quick
    r = m.resample(fps)
    _, report = clean(r)
    assert not report.glitches, report.table()


@pytest.mark.parametrize("fps,steps", [(24.0, 1), (120.0, 1), (240.0, 2)])
def test_the_reference_pose_exit_is_a_duration_not_a_frame(fps, steps):
    m = _load("cmu_12_01_walk.bvh")
    r = m if fps == 120.0 else m.resample(fps)
    assert reference_exit(r, CleanOptions()) == steps


def test_a_clip_that_starts_moving_has_no_reference_pose():
    for name in ("optitrack_hops_crouch.bvh", "pymo_walk.bvh", "bandai_walk.bvh"):
        m = _load(name)
        assert reference_exit(m, CleanOptions()) == 0, name
        assert reference_exit(m.resample(240.0), CleanOptions()) == 0, name


def test_a_flip_spread_over_two_frames_by_resampling_is_one_glitch():
    """The dance's real thigh flip (frames 245-253 at 120 Hz) resampled to 240 Hz: its entry
    and exit are each interpolated through 90 degrees, so the jumps pair twice; it is still
    one flip per joint, over the same time."""
    m = _load("cmu_05_10_dance_spins.bvh")
    _, native = clean(m)
    assert {(g.kind, g.joint, g.start, g.end) for g in native.glitches if g.joint in ("RightUpLeg", "RightFoot")} == {
        ("flip", "RightUpLeg", 245, 253),
        ("flip", "RightFoot", 245, 253),
    }
    _, report = clean(m.resample(240.0))
    mine = sorted((g.joint, g.kind, g.start, g.end) for g in report.glitches if g.joint in ("RightUpLeg", "RightFoot"))
    assert mine == [("RightFoot", "flip", 489, 507), ("RightUpLeg", "flip", 489, 507)], report.table()
