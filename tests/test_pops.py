"""Pops: a joint of the character that jumps in one frame where the actor's does not.

Before this figure the report said nothing when a foot lagged its target and then jumped
18 cm in one frame (the G1 on the 30 fps Bandai walk, frames 117-118: a 30 fps swing foot's
QP step, halved three times for the stance leg's second-order contact error, moved it an
eighth of the way per iteration).  The figure (``physmocap.metrics.fidelity.pops``), its
warning, and the two fixes it found (catch-up iterations for every position target that
accept the contacts' second-order error; a held swing foot's snap measured in centimetres a
frame as well as metres a second) are tested here.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, SHARED_DATA, retargeted, shared_file
from physmocap.metrics.fidelity import POP_M, fidelity, fidelity_warnings, pops, trajectory_fidelity

pytestmark = RETARGET_DIAGNOSTICS

G1 = "unitree_g1/g1_mocap_29dof.xml"


def _walking_leg(frames: int, fps: float) -> dict[str, np.ndarray]:
    """A hip, knee and ankle swinging smoothly forwards (metres, Z-up)."""
    t = np.arange(frames) / fps
    hip = np.stack([0.8 * t, 0 * t, 0.9 + 0 * t], axis=1)
    swing = 0.25 * np.sin(2 * np.pi * t)
    knee = hip + np.stack([0.5 * swing, 0 * t, -0.45 + 0 * t], axis=1)
    ankle = knee + np.stack([swing, 0 * t, -0.42 + 0 * t], axis=1)
    return {"left_hip": hip, "left_knee": knee, "left_ankle": ankle}


@pytest.mark.parametrize("fps", [30.0, 120.0])
def test_a_one_frame_jump_is_a_pop_at_any_frame_rate(fps):
    actor = _walking_leg(int(2 * fps), fps)
    char = {k: v.copy() for k, v in actor.items()}
    assert pops(actor, char).frames.size == 0  # a smooth copy does not pop
    k = int(fps)  # one second in: the ankle steps 4 cm and stays there
    char["left_ankle"][k:] += [0.04, 0.0, 0.0]
    found = pops(actor, char)
    assert set(found.frames) == {k - 1, k}  # the second difference sees both sides of the step
    assert found.worst_joint == "left_ankle" and found.worst_frame in (k - 1, k)
    assert found.worst_cm == pytest.approx(4.0, abs=0.5)
    assert found.warn_frames.size == 0  # 4 cm: counted, not warned about (POP_WARN_M)


def test_the_actors_own_jump_is_not_a_pop():
    """A source whose knee jumps (a glitch, a thigh turning over) carries the ankle with it:
    the character following it does not pop, on the knee nor on the ankle."""
    actor = _walking_leg(120, 60.0)
    actor["left_knee"][60:] += [0.0, 0.08, 0.0]
    char = {k: v.copy() for k, v in actor.items()}
    char["left_ankle"][60:] += [0.0, 0.08, 0.0]  # the actor's ankle did not move: the character's does
    assert pops(actor, char).frames.size == 0
    lost = _walking_leg(120, 60.0)
    lost["left_ankle"][58:63] = np.nan  # a lost joint excuses its frames
    jumped = {k: v.copy() for k, v in _walking_leg(120, 60.0).items()}
    jumped["left_ankle"][60:] += [0.05, 0.0, 0.0]
    assert pops(lost, jumped).frames.size == 0
    assert pops(_walking_leg(120, 60.0), jumped).frames.size == 2


def test_no_frames_or_no_common_joint():
    assert pops({}, {"left_knee": np.zeros((5, 3))}) is None
    empty = pops({"left_knee": np.zeros((0, 3))}, {"left_knee": np.zeros((0, 3))})
    assert empty.frames.size == 0 and empty.worst_cm == 0.0 and empty.worst_joint is None
    short = pops({"left_knee": np.zeros((2, 3))}, {"left_knee": np.ones((2, 3))})
    assert short.frames.size == 0  # no second difference on two frames


def test_pops_are_scaled_like_the_actor_and_warned_about():
    coarse = _walking_leg(40, 10.0)  # 10 fps: the swing's second difference is 10 cm
    big = {k: 2.0 * v for k, v in coarse.items()}  # a character twice the actor's size
    assert pops(coarse, big, scale=2.0).frames.size == 0
    assert pops(coarse, big, scale=1.0).frames.size > 0  # unscaled, its swing accelerates more
    actor = _walking_leg(120, 60.0)
    char = {k: v.copy() for k, v in actor.items()}
    char["left_knee"][70] += [0.0, 0.0, 0.06]  # one frame 6 cm off: a spike of 12 cm
    fid = fidelity(actor, char, fps=60.0)
    assert fid.pops.worst_frame == 70 and fid.pops.worst_cm == pytest.approx(12.0, abs=0.5)
    msgs = [m for m in fidelity_warnings(fid, offset=5) if "jumps where the actor does not" in m]
    assert len(msgs) == 1 and "75" in msgs[0] and "left_knee" in msgs[0], msgs
    assert fid.as_dict()["pops"]["frames"] == 3


def test_report_lists_pops(tmp_path):
    from physmocap.report import build_report, format_report

    shared_file("bandai_walk.bvh")
    _, traj = retargeted("bandai_walk.bvh", "humanoid")
    rep = build_report(traj, traj.source_motion, joint_indices=traj.joint_indices)
    assert rep["fidelity"]["pops"]["worst_cm"] >= 0.0
    assert "largest pop" in format_report(rep)


@pytest.mark.parametrize("character, before", [("g1", 11.3), ("humanoid", 8.0), ("robot", 9.1)])
def test_swing_feet_do_not_lag_and_jump_at_30_fps(character, before):
    """Before: on the 30 fps Bandai walk the G1's right foot lagged its target by 10 cm and
    jumped 18 cm in one frame (frames 117-118: a pop of 11.3 cm beyond the actor's), the
    humanoid's left ankle 8.0 cm, the robot's left foot 9.1 cm (held up over its stance foot
    for one frame, a snap of 3 cm a frame that the metres-a-second test let through)."""
    shared_file("bandai_walk.bvh")
    g1 = SHARED_DATA.parent / "robots" / G1
    if character == "g1" and not g1.exists():
        pytest.skip(f"the Unitree G1 is not at {g1}")
    name = str(g1) if character == "g1" else character
    _, traj = retargeted("bandai_walk.bvh", name)
    fid = trajectory_fidelity(traj, floor_contact=False)
    assert fid.pops.worst_cm < 0.65 * before, (fid.pops.worst_cm, fid.pops.worst_joint, fid.pops.worst_frame)
    assert fid.pops.warn_frames.size <= 1, fid.pops.warn_frames


def test_a_snap_is_centimetres_a_frame_too():
    """A held foot's offset that changes by 3 cm a frame snaps at 30 fps (0.9 m/s, under
    SNAP_SPEED: before, it did not); the same speed at 120 Hz (0.75 cm a frame) does not."""
    from physmocap.ik.transitions import SNAP_SPEED, _snapping_runs

    assert SNAP_SPEED > 0.9
    for fps, snaps in ((30.0, True), (120.0, False)):
        F = 40
        held = np.zeros(F, dtype=bool)
        held[10:30] = True
        offsets = np.zeros((F, 3))
        t = np.arange(10, 30)
        offsets[10:30, 1] = (0.9 / fps) * np.minimum(t - 9, 30 - t)  # out at 0.9 m/s, and back
        run = _snapping_runs(offsets, held, fps)
        assert bool(run[10:30].all()) == snaps and not run[:10].any() and not run[30:].any(), (fps, run)


def test_catch_up_overshoot_is_on_by_default_and_validated():
    from physmocap.errors import OptionError
    from physmocap.ik.solver import SolverOptions

    assert SolverOptions().catch_up_overshoot == pytest.approx(1e-3) and SolverOptions().contact_overshoot == 0.0
    for bad in (-1e-3, float("nan")):
        with pytest.raises(OptionError):
            SolverOptions(catch_up_overshoot=bad)


@pytest.mark.parametrize("name", ["humanoid", "robot"])
def test_the_catch_up_allowance_is_only_behind_a_fast_target(name):
    """The 1 mm contact allowance of the catch-up iterations, and the oriented targets' lags,
    count only behind a target that moved more than ``catch_up`` since the previous frame.
    On every catch-up (the first version) the PyMO walk humanoid's toes flapped after
    toe-off and the G1's left wrist turned 90 degrees from the actor's on the dance."""
    from test_qp import _setup

    solver = _setup(name, 0)
    c = solver.options.catch_up
    data = solver.configuration.data
    names = solver.names
    here = np.array([solver.character.tracked[n].position(solver.model, data) for n in names])
    ori = np.tile([0.0, 0.0, 0.0, 1.0], (len(names), 1))
    valid = np.ones(len(names), dtype=bool)
    far = here + np.array([0.0, 0.0, 2.0 * c])  # every target 10 cm above its joint
    solver._set_targets(far, ori, valid)
    solver._set_targets(far, ori, valid)  # ... and still there: a slow lag
    assert solver._lagging() == (True, False)
    solver._set_targets(far + np.array([2.0 * c, 0.0, 0.0]), ori, valid)  # the targets jump 10 cm
    assert solver._lagging() == (True, True)
    solver.reset()
    solver._set_targets(here, ori, valid)  # after a reset no step is known: nothing is fast
    assert not solver._lagging()[1]
