"""Issue 9, item 6: one validated configuration, one per-frame pipeline, typed results."""

from __future__ import annotations

import numpy as np
import pytest

import physmocap
from physmocap.errors import OptionError
from physmocap.ik import FrameRetargeter, RetargetConfig
from physmocap.ik.contacts import detect_contacts
from physmocap.ik.retarget import map_motion, retarget, solve_targets
from physmocap.ik.stream import StreamingRetargeter, stream_motion
from physmocap.ik.targets import build_targets
from physmocap.models import load_character
from physmocap.trajectory import SolverStats
from conftest import RETARGET_DIAGNOSTICS

pytestmark = RETARGET_DIAGNOSTICS


@pytest.fixture(scope="module")
def walk():
    return physmocap.load_motion("example").slice_frames(1, 61)


def test_flat_options_land_in_their_stage():
    c = RetargetConfig().with_options(max_iterations=7, plant=False, scale_root=False, ease_time=0.2)
    assert (c.solver.max_iterations, c.plant.plant, c.targets.scale_root, c.plant.ease_time) == (7, False, False, 0.2)
    assert RetargetConfig().solver.max_iterations != 7  # with_options returns a copy


@pytest.mark.parametrize(
    "options,needle",
    [
        ({"bogus": 1}, "unknown retarget option"),
        ({"max_iterations": 0}, "max_iterations must be > 0"),
        ({"max_iterations": 2.5}, "whole number"),
        ({"clearance": -0.01}, "clearance must be >= 0"),
        ({"ease_time": float("nan")}, "ease_time must be a finite number"),
        ({"floor": 0.3}, "floor must be true or false"),  # the floor constraint, not the actor's floor
        ({"source_floor": "low"}, "source_floor must be a finite number"),
        ({"limit_gain": 1.5}, "limit_gain"),
    ],
)
def test_bad_options_are_refused_by_name(options, needle):
    with pytest.raises(OptionError, match=needle):
        RetargetConfig().with_options(**options)


def test_config_and_flat_options_give_the_same_retarget(walk):
    a = retarget(walk, None, RetargetConfig().with_options(max_iterations=3), start=0, progress=False)
    b = retarget(walk, None, start=0, progress=False, max_iterations=3)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    assert isinstance(a.solver, SolverStats) and a.solver.iterations.shape == (walk.num_frames,)
    assert a.contacts is not None and a.source_motion is not None and a.joint_indices and a.fidelity is not None
    with pytest.raises(OptionError, match="RetargetConfig"):
        retarget(walk, None, {"max_iterations": 3}, progress=False)


def test_solve_targets_leaves_the_callers_targets_alone(walk):
    ch = load_character()
    idx = map_motion(walk)
    contacts = detect_contacts(walk, idx)
    targets = build_targets(walk, idx, ch, floor=contacts.floor)
    before = targets.positions.copy()
    info_keys = set(targets.info)
    traj = solve_targets(targets, ch, labels=contacts.labels, progress=False)
    np.testing.assert_array_equal(targets.positions, before)
    assert set(targets.info) == info_keys
    assert traj.targets is not targets and "raw_positions" in traj.targets.info


def test_offline_and_streaming_run_the_same_frame_pipeline(walk, monkeypatch):
    calls = []
    original = FrameRetargeter.solve

    def counting(self, positions, orientations, valid, labels=None, guide=None):
        calls.append((self.anchored, positions.copy()))
        return original(self, positions, orientations, valid, labels, guide)

    monkeypatch.setattr(FrameRetargeter, "solve", counting)
    retarget(walk, None, start=0, progress=False)  # two passes: the last smooths contact changes
    offline = len(calls)
    stream_motion(walk)
    assert offline == 2 * walk.num_frames and len(calls) == 3 * walk.num_frames
    assert {a for a, _ in calls[:offline]} == {False} and {a for a, _ in calls[offline:]} == {True}


def test_frame_pipeline_does_not_modify_its_inputs(walk):
    ch = load_character()
    idx = map_motion(walk)
    targets = build_targets(walk, idx, ch)
    frame = FrameRetargeter(ch, targets.names, targets.has_orientation, walk.fps)
    labels = {"left_heel": True, "left_toe": True, "right_heel": True, "right_toe": True}
    for t in range(3):
        p, o, v = targets.positions[t].copy(), targets.orientations[t].copy(), targets.valid[t].copy()
        result = frame.solve(p, o, v, dict(labels))
        np.testing.assert_array_equal(p, targets.positions[t])
        np.testing.assert_array_equal(o, targets.orientations[t])
        assert result.qpos.shape == (ch.model.nq,) and np.isfinite(result.qpos).all()


def test_streaming_source_floor_is_the_actors_floor(walk):
    live = StreamingRetargeter(None, skeleton=walk.skeleton, fps=walk.fps, translated=walk.translated, source_floor=0.0)
    assert live.config.targets.source_floor == 0.0 and live.config.solver.floor is True
    with pytest.raises(OptionError, match="floor must be true or false"):
        StreamingRetargeter(None, skeleton=walk.skeleton, fps=walk.fps, floor=0.0)


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_the_upper_body_follows_a_pelvis_that_lags_its_target(walk, character):
    """FrameRetargeter: a pelvis 5 cm from its target moves the targets above the chest (neck,
    head, clavicles, arms) by what exceeds PELVIS_LAG_FREE, and nothing else; option off, nothing."""
    from physmocap.ik.frame import PELVIS_LAG_FREE
    from physmocap.ik.solver import SolverOptions

    ch = load_character(character)
    targets = build_targets(walk, map_motion(walk), ch)
    names = list(targets.names)
    frame = FrameRetargeter(ch, targets.names, targets.has_orientation, walk.fps)
    frame._lag = np.array([0.05, 0.0, 0.0])
    p = targets.positions[0]
    moved = frame._follow_pelvis(p)
    shift = moved - p
    legs = ("hip", "knee", "ankle", "toe", "toe_end")
    upper = {n for n in names if n not in ("pelvis", "spine", "chest") and n.split("_", 1)[-1] not in legs}
    assert {"neck", "head", "left_wrist", "right_elbow"} <= upper
    for i, n in enumerate(names):
        expect = 0.05 - PELVIS_LAG_FREE if n in upper else 0.0
        assert np.allclose(shift[i], [expect, 0.0, 0.0]), (n, shift[i])
    off = FrameRetargeter(ch, targets.names, targets.has_orientation, walk.fps, SolverOptions(upper_body_follows_pelvis=False))
    off._lag = frame._lag
    np.testing.assert_array_equal(off._follow_pelvis(p), p)
