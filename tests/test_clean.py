"""Glitch detection and repair (issue 12, first part) on the bundled walk with injected glitches."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from physmocap.cli import main
from physmocap.clean import clean
from physmocap.clean.correct import BRIDGES
from physmocap.rotations import Rotation, quat_mul
from physmocap.sources import load_motion


@pytest.fixture(scope="module")
def walk():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_motion("example")


def _joint(m, name):
    return m.skeleton.names.index(name)


def _led_by(corrected: str) -> str:
    """The estimate with the largest share in a repair's report ("cubic" of "blend of cubic
    59% + mirrored 41%")."""
    from physmocap.clean.correct import blend_shares

    return next(iter(blend_shares(corrected)))


def _with(m, j, frames, q=None, hold=False):
    R = np.array(m.rotations, copy=True)
    if hold:
        R[frames, j] = R[frames[0] - 1, j]
    else:
        R[frames, j] = quat_mul(np.broadcast_to(q, (len(frames), 4)), R[frames, j])
    return dataclasses.replace(m, rotations=R)


def test_untouched_walk_has_almost_no_glitch(walk):
    _, report = clean(walk)
    flagged = {t for g in report.glitches for t in range(g.start, g.end + 1)}
    assert len(flagged) < 0.005 * walk.num_frames


@pytest.mark.parametrize(
    "kind,deg,frames",
    [("spike", 60.0, [200]), ("spike", 45.0, list(range(200, 230))), ("flip", 180.0, [150, 151, 152])],
)
def test_rotation_glitches_are_found_named_and_repaired(walk, kind, deg, frames):
    j = _joint(walk, "LeftForeArm")
    q = Rotation.from_rotvec(np.radians(deg) * np.array([0.0, 0.6, 0.8])).as_quat()
    bad = _with(walk, j, frames, q)
    fixed, report = clean(bad)
    mine = [g for g in report.glitches if g.joint == "LeftForeArm"]
    assert len(mine) == 1 and mine[0].kind == kind and (mine[0].start, mine[0].end) == (frames[0], frames[-1])
    assert _led_by(mine[0].corrected) in (("offset removed",) if len(frames) >= 0.15 * walk.fps else BRIDGES)
    P0, Pb, Pf = walk.world_positions(), bad.world_positions(), fixed.world_positions()
    before = np.linalg.norm(Pb[frames] - P0[frames], axis=-1).max()
    after = np.linalg.norm(Pf[frames] - P0[frames], axis=-1).max()
    assert after < 0.25 * before
    untouched = np.ones(walk.num_frames, bool)
    untouched[frames] = False
    assert np.array_equal(fixed.rotations[untouched], bad.rotations[untouched])


def test_frozen_joint_is_found(walk):
    j = _joint(walk, "RightUpLeg")
    frames = list(range(300, 330))
    fixed, report = clean(_with(walk, j, frames, hold=True))
    mine = [g for g in report.glitches if g.joint == "RightUpLeg" and g.kind == "frozen"]
    assert len(mine) == 1 and mine[0].start == 300 and mine[0].end == 329


def test_a_knee_clamped_straight_in_a_one_stride_clip_is_not_frozen_but_a_freeze_there_is(walk):
    """CMU's solver holds each knee at the identity (straight) through every stance: in the
    whole clip each knee holds it in several runs, in a clip cut to one stride the right knee
    holds it once, and only the left knee's runs say it is a clamp.  A real freeze next to
    it (another value, held while the body moves) is still found."""
    stride = walk.slice_frames(1, 1 + int(1.5 * walk.fps))
    j = _joint(stride, "RightLeg")
    held = np.all(stride.rotations[1:, j] == stride.rotations[:-1, j], axis=1)
    assert held.sum() >= 0.1 * stride.fps  # the clamp is there, and long enough to be taken for a freeze
    _, report = clean(stride)
    assert not [g for g in report.glitches if g.kind == "frozen"]
    frames = list(range(120, 150))
    _, report = clean(_with(stride, _joint(stride, "LeftLeg"), frames, hold=True))
    mine = [g for g in report.glitches if g.kind == "frozen"]
    assert [(g.joint, g.start, g.end) for g in mine] == [("LeftLeg", 120, 149)]


def test_fast_real_motion_at_low_rates_is_not_a_glitch(walk):
    low = walk.resample(30.0)
    _, report = clean(low)
    assert not [g for g in report.glitches if g.kind != "discontinuity"]


def test_cli_writes_a_drop_in_replacement(walk, tmp_path, capsys):
    from physmocap.export.bvh import write_bvh

    j = _joint(walk, "LeftForeArm")
    q = Rotation.from_rotvec(np.radians(70) * np.array([1.0, 0.0, 0.0])).as_quat()
    src = tmp_path / "glitchy.bvh"
    write_bvh(_with(walk, j, [100, 101], q), src)
    out, rep = tmp_path / "clean.bvh", tmp_path / "g.json"
    assert main(["clean", str(src), "-o", str(out), "--report", str(rep)]) == 0
    a, b = src.read_text().splitlines(), out.read_text().splitlines()
    assert len(a) == len(b) and a[: a.index("MOTION") + 3] == b[: b.index("MOTION") + 3]
    changed = [k for k, (x, y) in enumerate(zip(a, b)) if x != y]
    motion_line = a.index("MOTION") + 3
    assert changed and all(k - motion_line in (100, 101) for k in changed)
    assert '"kind": "spike"' in rep.read_text()
    assert main(["clean", str(src), "-o", str(tmp_path / "x.mp4")]) == 2


def test_untouched_walk_is_within_its_ranges_of_motion(walk):
    from physmocap.clean.detect import anatomical_glitches

    assert anatomical_glitches(walk) == []


@pytest.mark.parametrize("joint,excess,frames", [("left_knee", 2.0, range(250, 255)), ("right_elbow", 60.0, range(100, 101))])
def test_hyperextension_is_found_named_and_repaired(walk, joint, excess, frames):
    from physmocap.clean.anatomy import bend_past_range, motion_angles
    from physmocap.ik.retarget import map_motion

    j, new = bend_past_range(walk, joint, frames, excess)
    R = np.array(walk.rotations, copy=True)
    R[list(frames)] = R[list(frames)]
    R[list(frames), j] = new
    bad = dataclasses.replace(walk, rotations=R)
    fixed, report = clean(bad)
    side, limb = joint.split("_")
    mine = [g for g in report.glitches if g.movement == f"{side} {limb} hyperextension"]
    assert len(mine) == 1, report.table()
    g = mine[0]
    assert (g.start, g.end) == (frames[0], frames[-1]) and g.joint == walk.skeleton.names[j]
    assert g.plane == "sagittal" and _led_by(g.corrected) == "cubic"
    # a sudden bend is a spike that names its movement; its excess is the anatomical glitch's severity
    from physmocap.clean.detect import anatomical_glitches

    alone = [a for a in anatomical_glitches(bad) if a.movement == g.movement]
    assert len(alone) == 1 and abs(alone[0].severity - excess) < 1e-6
    # repaired: back within the range, only that joint on those frames changed
    angles, _ = motion_angles(fixed, map_motion(fixed))
    assert np.all(angles[f"{joint}_flexion"][list(frames)] > -10.0)
    untouched = np.ones(walk.num_frames, bool)
    untouched[list(frames)] = False
    assert np.array_equal(fixed.rotations[untouched], bad.rotations[untouched])


def test_long_out_of_range_span_is_reported_not_changed(walk):
    from physmocap.clean.anatomy import bend_past_range

    frames = range(100, 100 + int(walk.fps))  # 1 s: longer than a glitch
    j, new = bend_past_range(walk, "left_knee", frames, 20.0)
    R = np.array(walk.rotations, copy=True)
    R[list(frames), j] = new
    bad = dataclasses.replace(walk, rotations=R)
    fixed, report = clean(bad)
    mine = [g for g in report.glitches if g.kind == "anatomical"]
    assert mine and all(not g.corrected for g in mine)
    assert "left knee hyperextension (sagittal)" in report.table()


def test_angles_do_not_depend_on_the_files_euler_order(walk, tmp_path):
    from physmocap.clean.anatomy import motion_angles
    from physmocap.export.bvh import write_bvh
    from physmocap.ik.retarget import map_motion

    path = write_bvh(walk.slice_frames(0, 120), tmp_path / "xyz.bvh", rotation_order="XYZ", precision=9)
    other = load_motion(path)
    a, _ = motion_angles(walk.slice_frames(0, 120), map_motion(walk))
    b, _ = motion_angles(other, map_motion(other))
    assert set(a) == set(b)
    for k in a:
        np.testing.assert_allclose(a[k], b[k], atol=1e-3, err_msg=k)


def test_unmappable_skeleton_names_the_joints_it_cannot_check(tmp_path):
    from physmocap.clean.detect import anatomical_glitches

    text = (
        "HIERARCHY\nROOT a\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  JOINT b\n  {\n    OFFSET 0 10 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 10 0\n    }\n  }\n}\n"
        "MOTION\nFrames: 3\nFrame Time: 0.0333\n" + "0 0 0 0 0 0 0 0 0\n" * 3
    )
    path = tmp_path / "stick.bvh"
    path.write_text(text)
    m = load_motion(path)
    with pytest.warns(Warning, match="cannot check ranges of motion for joints .*left_knee"):
        assert anatomical_glitches(m) == []
    with pytest.warns(Warning, match="cannot check ranges of motion for joints .*left_knee"):
        _, report = clean(m)  # the other checks still run
    assert report.frames == 3


def test_left_right_swap_on_positions_is_found_and_traded_back(walk):
    from physmocap.motion import Motion

    W = walk.world_positions()
    names = list(walk.skeleton.names)
    jl, jr = names.index("LeftLeg"), names.index("RightLeg")
    P = W.copy()
    P[200:210, [jl, jr]] = P[200:210, [jr, jl]]
    fixed, report = clean(Motion(walk.skeleton, walk.fps, positions=P, source="swapped"))
    swaps = [g for g in report.glitches if g.kind == "lr_swap"]
    assert {(g.joint, g.start, g.end) for g in swaps} == {("LeftLeg", 200, 209), ("RightLeg", 200, 209)}
    assert all(g.corrected == "swapped back" for g in swaps)
    assert not [g for g in report.glitches if g.kind == "bone_stretch"]  # explained by the swap
    np.testing.assert_array_equal(fixed.positions, W)
    _, untouched = clean(Motion(walk.skeleton, walk.fps, positions=W, source="walk"))
    assert not untouched.glitches


def test_cli_plots_mark_the_glitched_spans(walk, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from physmocap.clean.anatomy import bend_past_range
    from physmocap.export.bvh import write_bvh

    j, new = bend_past_range(walk, "left_knee", range(300, 306), 25.0)
    R = np.array(walk.rotations, copy=True)
    R[300:306, j] = new
    src = tmp_path / "knee.bvh"
    write_bvh(dataclasses.replace(walk, rotations=R), src)
    plots = tmp_path / "plots"
    assert main(["clean", str(src), "--plots", str(plots)]) == 0
    out = capsys.readouterr().out
    assert "left knee hyperextension (sagittal)" in out
    names = sorted(p.name for p in plots.iterdir())
    assert "anatomy.png" in names and f"{walk.skeleton.names[j]}.png" in names
    first = (plots / "anatomy.png").read_bytes()
    assert first[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["clean", str(src), "--plots", str(plots)]) == 0
    assert (plots / "anatomy.png").read_bytes() == first  # deterministic
    assert main(["clean", str(src), "--plots", str(src)]) == 2  # a file, not a directory


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_segment_found_with_its_exact_span_at_any_rate_and_its_offset_taken_off(walk, fps):
    """A 0.3 s offset over a moving joint: the exit undoes the entry whatever the joint did
    meanwhile, at any frame rate; the repair brings the real motion back."""
    m = walk if fps == walk.fps else walk.resample(fps)
    j = _joint(m, "LeftForeArm")
    a = int(round(1.5 * fps))
    frames = list(range(a, a + int(round(0.3 * fps))))
    q = Rotation.from_rotvec(np.radians(35.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    bad = _with(m, j, frames, q)
    fixed, report = clean(bad)
    mine = [g for g in report.glitches if g.joint == "LeftForeArm"]
    assert [(g.kind, g.start, g.end) for g in mine] == [("spike", frames[0], frames[-1])]
    assert mine[0].corrected == "offset removed"
    P0, Pb, Pf = m.world_positions(), bad.world_positions(), fixed.world_positions()
    before = np.sqrt(np.mean(np.sum((Pb[frames] - P0[frames]) ** 2, axis=-1)))
    after = np.sqrt(np.mean(np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1)))
    assert after < 0.1 * before


def test_spike_below_the_speed_limit_at_30_hz_is_found(walk):
    """25 degrees out and back in one frame at 30 Hz is 750 deg/s, slower than a fast real
    joint: the jump that returns is the evidence, not the speed."""
    m = walk.resample(30.0)
    j = _joint(m, "LeftForeArm")
    q = Rotation.from_rotvec(np.radians(25.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    _, report = clean(_with(m, j, [60], q))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "LeftForeArm"] == [("spike", 60, 60)]


def test_two_unrelated_jumps_do_not_make_a_spike(walk):
    """A jump and, later, a jump of the same size about another axis: the second does not
    undo the first, so no span between them is flagged (a noisy joint's two snaps)."""
    j = _joint(walk, "LeftForeArm")
    R = np.array(walk.rotations, copy=True)
    qa = Rotation.from_rotvec(np.radians(30.0) * np.array([1.0, 0.0, 0.0])).as_quat()
    qb = Rotation.from_rotvec(np.radians(30.0) * np.array([0.0, 0.0, 1.0])).as_quat()
    R[200:, j] = quat_mul(np.broadcast_to(qa, (len(R) - 200, 4)), R[200:, j])
    R[230:, j] = quat_mul(np.broadcast_to(qb, (len(R) - 230, 4)), R[230:, j])
    from physmocap.clean import CleanOptions

    bad = dataclasses.replace(walk, rotations=R)
    _, report = clean(bad)
    mine = [g for g in report.glitches if g.joint == "LeftForeArm"]
    assert not [g for g in mine if g.kind in ("spike", "flip")]
    # the first, mostly a twist, moves the hand 3 cm: below jump_distance, a solver's pop
    assert {(g.kind, g.start) for g in mine if g.kind != "anatomical"} == {("discontinuity", 230)}
    _, report = clean(bad, CleanOptions(jump_distance=0.02))
    mine = [g for g in report.glitches if g.joint == "LeftForeArm" and g.kind != "anatomical"]
    assert {(g.kind, g.start) for g in mine} == {("discontinuity", 200), ("discontinuity", 230)}


def test_a_pop_the_next_joint_undoes_is_not_a_spike(walk):
    """A spine joint popping 20 degrees out and back while its child turns back the same
    (a solver moving a bend between consecutive joints: the chest and arms stay put) is no
    spike; the same offset carried by the child is one."""
    j, k = _joint(walk, "Spine"), _joint(walk, "Spine1")
    frames = list(range(200, 210))
    q = Rotation.from_rotvec(np.radians(20.0) * np.array([0.0, 0.6, 0.8])).as_quat()
    R = np.array(walk.rotations, copy=True)
    R[frames, j] = quat_mul(R[frames, j], np.broadcast_to(q, (len(frames), 4)))  # in the joint's own frame
    R[frames, k] = quat_mul(np.broadcast_to(Rotation.from_quat(q).inv().as_quat(), (len(frames), 4)), R[frames, k])
    _, report = clean(dataclasses.replace(walk, rotations=R))
    assert not [g for g in report.glitches if g.kind in ("spike", "flip")]
    _, report = clean(_with(walk, j, frames, q))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "Spine"] == [("spike", 200, 209)]


def test_frozen_repair_keeps_the_joints_speed_and_leaves_no_catch_up_jump(walk):
    j = _joint(walk, "RightUpLeg")
    frames = list(range(300, 340))
    bad = _with(walk, j, frames, hold=True)
    fixed, report = clean(bad)
    mine = [g for g in report.glitches if g.joint == "RightUpLeg"]
    assert [(g.kind, g.start, g.end) for g in mine] == [("frozen", 300, 339)]  # no discontinuity at 340
    from physmocap.clean.detect import joint_angles_step

    step = joint_angles_step(np.asarray(fixed.rotations))[:, j]
    assert step[299:342].max() < 3.0 * max(step[280:299].max(), step[341:360].max())


def test_a_pop_to_a_pose_the_joint_takes_anyway_is_not_a_spike(walk):
    """A forearm set, for 0.2 s, to a rotation it holds elsewhere in the clip (a solved joint
    popping to a pose it reaches anyway) is no spike; the same span offset 35 degrees about an
    axis the joint never turns about is one."""
    j = _joint(walk, "LeftForeArm")
    R = np.array(walk.rotations, copy=True)
    frames = list(range(200, 224))
    far = 300 + int(np.argmin(np.abs(R[300:, j] @ R[199, j])))  # its own pose farthest from frame 199
    R[frames, j] = R[far, j]
    step = np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(R[199, j] * R[200, j])), 0, 1)))
    assert step > 10.0  # a real jump in and out
    _, report = clean(dataclasses.replace(walk, rotations=R))
    assert not [g for g in report.glitches if g.joint == "LeftForeArm" and g.kind in ("spike", "flip")]
    q = Rotation.from_rotvec(np.radians(35.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    _, report = clean(_with(walk, j, frames, q))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "LeftForeArm"] == [("spike", 200, 223)]


def test_slow_out_and_back_at_30_hz_is_not_a_spike(walk):
    """10 degrees out and back at 30 Hz is 300 deg/s: slower than a walking knee, not a glitch."""
    from physmocap.clean import CleanOptions

    m = walk.resample(30.0)
    j = _joint(m, "LeftForeArm")
    q = Rotation.from_rotvec(np.radians(11.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    bad = _with(m, j, [60, 61], q)
    _, report = clean(bad)
    assert not [g for g in report.glitches if g.joint == "LeftForeArm" and g.kind == "spike"]
    _, report = clean(bad, CleanOptions(pair_speed=200.0))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "LeftForeArm"] == [("spike", 60, 61)]


@pytest.mark.parametrize("order", ["XYZ", "ZYX"])
def test_detections_do_not_depend_on_the_files_euler_order(walk, tmp_path, order):
    """The same glitched motion written with other rotation channels is found the same."""
    from physmocap.export.bvh import write_bvh

    m = walk.slice_frames(0, 400)
    j, k = _joint(m, "LeftForeArm"), _joint(m, "RightUpLeg")
    q = Rotation.from_rotvec(np.radians(40.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    bad = _with(_with(m, j, list(range(100, 130)), q), k, list(range(200, 230)), hold=True)
    bad = _with(bad, _joint(m, "RightForeArm"), [300], Rotation.from_rotvec(np.radians(180.0) * np.array([1.0, 0, 0])).as_quat())
    ref = write_bvh(bad, tmp_path / "ref.bvh", precision=9)
    other = write_bvh(bad, tmp_path / f"{order}.bvh", rotation_order=order, precision=9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = clean(load_motion(ref))[1].glitches
        b = clean(load_motion(other))[1].glitches
    key = lambda g: (g.kind, g.joint, g.start, g.end, g.movement)  # noqa: E731
    assert sorted(map(key, a)) == sorted(map(key, b))
    assert {g.kind for g in a} >= {"spike", "frozen", "flip"}
    for ga, gb in zip(sorted(a, key=key), sorted(b, key=key)):
        assert abs(ga.severity - gb.severity) < 0.05


def test_shortened_benchmark_on_the_bundled_walk(walk):
    """scripts/glitch_benchmark.py's injection, 3 glitches of each type into the bundled walk:
    every type found with recall and precision of at least 0.95 (the walk's own flag, a toe
    stepping 15 degrees in one frame, left out as the benchmark's injected precision does)."""
    from conftest import load_script

    bench = load_script("glitch_benchmark")
    names = {n: j for j, n in enumerate(walk.skeleton.names)}
    own = bench._flagged(clean(walk)[1], names)
    assert len({t for _, t in own}) < 0.005 * walk.num_frames
    for ti, kind in enumerate(bench.TYPES):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            glitched, truth, faint = bench.inject(walk, np.random.default_rng([7, ti]), 3, (kind,))
            _, report = clean(glitched)
        det = bench._flagged(report, names) - faint - (own - truth[kind])
        p, r, _ = bench._prf(len(det & truth[kind]), len(det - truth[kind]), len(truth[kind] - det))
        assert r >= 0.95 and p >= 0.95, (kind, p, r)


def test_frozen_knee_gets_the_motion_the_body_makes_elsewhere(walk):
    """A knee frozen for 0.4 s of a walk: no curve knows the swing it hides, but the other
    strides (or the other leg's, mirrored) do, and so does the rest of the body (the knee's
    motion regressed on it); the matched or regressed motion takes off most of the error."""
    j = _joint(walk, "RightLeg")
    frames = list(range(300, 348))
    bad = _with(walk, j, frames, hold=True)
    fixed, report = clean(bad)
    mine = [(g.kind, g.start, g.end, _led_by(g.corrected)) for g in report.glitches if g.joint == "RightLeg"]
    assert mine in ([("frozen", 300, 347, led)] for led in BRIDGES if led != "cubic")
    P0, Pb, Pf = walk.world_positions(), bad.world_positions(), fixed.world_positions()
    before = np.sqrt(np.mean(np.sum((Pb[frames] - P0[frames]) ** 2, axis=-1)))
    after = np.sqrt(np.mean(np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1)))
    assert after < 0.35 * before
    untouched = np.ones(walk.num_frames, bool)
    untouched[frames] = False
    assert np.array_equal(fixed.rotations[untouched], bad.rotations[untouched])


def _span_rms(m, reference, frames) -> float:
    P, P0 = m.world_positions()[frames], reference.world_positions()[frames]
    return float(np.sqrt(np.mean(np.sum((P - P0) ** 2, axis=-1))))


def test_frozen_thigh_gets_the_other_legs_motion_mirrored(walk):
    """A left thigh frozen for 0.4 s: the right leg, half a stride later and reflected
    across the body's midplane, shows its swing better than the left leg's other strides."""
    from physmocap.clean import CleanOptions
    from physmocap.clean.correct import _matcher, _mirror, correct_glitches
    from physmocap.clean.detect import Glitch, canonical_joints

    twin, reflect = _mirror(walk, canonical_joints(walk))
    names = walk.skeleton.names
    assert names[twin[_joint(walk, "LeftUpLeg")]] == "RightUpLeg" and twin[_joint(walk, "Spine")] == _joint(walk, "Spine")
    assert abs(reflect[0, 0] + 1.0) < 0.01  # the skeleton's left-right axis is x
    j, frames = _joint(walk, "LeftUpLeg"), list(range(300, 348))
    bad = _with(walk, j, frames, hold=True)
    glitch = [Glitch("frozen", "LeftUpLeg", 300, 347, 1.0)]
    matcher = _matcher(bad, glitch, CleanOptions(), canonical_joints(bad))
    errors = {}
    for mirrored in (False, True):
        R = np.array(bad.rotations, copy=True)
        R[frames, j] = matcher.bridge(j, 300, 347, None, mirrored)
        errors[mirrored] = _span_rms(dataclasses.replace(walk, rotations=R), walk, frames)
    assert errors[True] < 0.5 * errors[False], errors
    # chosen on the thigh's own motion next to the span (no foot held: contact_height ~ 0)
    fixed, done = correct_glitches(bad, glitch, CleanOptions(contact_height=1e-6))
    assert _led_by(done[0].corrected) == "mirrored"
    assert _span_rms(fixed, walk, frames) < 0.05 * _span_rms(bad, walk, frames)


def test_bridges_that_rebuild_the_joint_about_as_well_are_averaged(walk):
    """Where two or three bridges rebuild the joint's own motion next to the span about as
    well (``blend_ratio``), their mean, weighted by the inverse of that error, is used;
    ``blend_ratio=1`` keeps the best one alone.  The report names the blend, not the best
    bridge alone: "blend of cubic 59% + mirrored 41%", each bridge's share of the weights."""
    from physmocap.clean import CleanOptions
    from physmocap.clean.correct import _bridge, _hermite, _matcher, _pseudo_gaps, blend_shares
    from physmocap.clean.detect import Glitch, _angle, canonical_joints
    from physmocap.clean.regress import Departure, Regression

    j, frames = _joint(walk, "LeftForeArm"), list(range(200, 248))
    bad = _with(walk, j, frames, hold=True)
    matcher = _matcher(bad, [Glitch("frozen", "LeftForeArm", 200, 247, 1.0)], CleanOptions(), canonical_joints(bad))
    R = np.asarray(bad.rotations)
    regression = Regression(R, matcher.M, matcher.animated, matcher.bad, j, 200, 247, CleanOptions().regress_ridge)
    regression.choose_ridge(_pseudo_gaps(200, 247, len(R)), 48)
    found = [_hermite(R[:, j], 199, 248), matcher.bridge(j, 200, 247), matcher.bridge(j, 200, 247, None, True),
             *regression.estimates(200, 247)]
    departure = Departure(R, matcher.animated, matcher.bad, j, 200, 247, CleanOptions().regress_ridge)
    departure.choose_ridge(_pseudo_gaps(200, 247, len(R)))
    found.append(departure.estimate(200))
    names = list(BRIDGES)
    alone, name = _bridge(R, j, 200, 247, matcher, 1.0)
    assert any(np.allclose(alone, q) for q in found)
    mixed, name_mixed = _bridge(R, j, 200, 247, matcher, 1e9)  # every bridge counts
    assert name in names
    shares = blend_shares(name_mixed)
    assert name_mixed.startswith("blend of ") and sorted(shares) == sorted(names)
    assert next(iter(shares)) == name and abs(sum(shares.values()) - 1.0) <= 0.015  # the best leads; whole percents
    spread = max(_angle(a, b).max() for a in found for b in found)
    assert min(_angle(mixed, q).max() for q in found) > 0.01 * spread  # none of them alone
    assert max(_angle(mixed, q).max() for q in found) <= spread + 1e-6  # among them


def test_frozen_thigh_in_stance_keeps_its_foot_planted(walk):
    """A right thigh frozen for 0.4 s while its foot stands: the hip moves on, the knee and
    ankle rotations are good, so the thigh is turned to keep the toes where they stand; the
    bridge alone slides them."""
    from physmocap.clean import CleanOptions
    from physmocap.clean.correct import correct_glitches
    from physmocap.clean.detect import Glitch

    j, frames = _joint(walk, "RightUpLeg"), list(range(200, 248))
    bad = _with(walk, j, frames, hold=True)
    glitch = [Glitch("frozen", "RightUpLeg", 200, 247, 1.0)]
    fixed, done = correct_glitches(bad, glitch)
    loose, done_loose = correct_glitches(bad, glitch, CleanOptions(contact_height=1e-6))
    assert done[0].corrected.endswith(", on contact") and "contact" not in done_loose[0].corrected
    assert _span_rms(fixed, walk, frames) < 0.4 * _span_rms(loose, walk, frames)
    toe = _joint(walk, "RightToeBase_End")
    assert np.abs(fixed.world_positions()[frames, toe] - walk.world_positions()[frames, toe]).max() < 0.01
    untouched = np.ones(np.shape(fixed.rotations)[:2], bool)
    untouched[frames, j] = False
    assert np.array_equal(np.asarray(fixed.rotations)[untouched], np.asarray(bad.rotations)[untouched])


def test_a_second_glitch_below_the_joint_leaves_the_stance_before_it(walk):
    """The knee frozen too, from the thigh's last 8 frames on: the foot is no guide where the
    knee is wrong (nor on the good frames after the thigh's span), but it still stands on the
    frames before the knee's freeze."""
    from physmocap.clean.correct import correct_glitches
    from physmocap.clean.detect import Glitch

    thigh, knee = _joint(walk, "RightUpLeg"), _joint(walk, "RightLeg")
    bad = _with(_with(walk, thigh, list(range(200, 248)), hold=True), knee, list(range(240, 276)), hold=True)
    glitches = [Glitch("frozen", "RightUpLeg", 200, 247, 1.0), Glitch("frozen", "RightLeg", 240, 275, 1.0)]
    fixed, done = correct_glitches(bad, glitches)
    assert done[0].corrected.endswith(", on contact")
    assert _span_rms(fixed, walk, list(range(200, 240))) < 0.002  # 0.5 cm without the stance


def test_frozen_arm_of_a_still_body_is_found_by_its_catch_up(walk):
    """The body standing (every other joint still but for noise) while the forearm moves:
    a forearm held for 0.25 s is found by the jump it makes to catch up, not by the body."""
    m = walk.slice_frames(0, 400)
    j = _joint(m, "LeftForeArm")
    R = np.array(m.rotations, copy=True)
    rng = np.random.default_rng(0)
    noise = Rotation.from_rotvec(np.radians(0.01) * rng.normal(size=(300 * R.shape[1], 3))).as_quat()
    still = quat_mul(noise.reshape(300, R.shape[1], 4), np.broadcast_to(R[100], (300, R.shape[1], 4)))
    others = [k for k in range(R.shape[1]) if k != j]
    R[100:400, others] = still[:, others]
    R[200:230, j] = R[199, j]
    _, report = clean(dataclasses.replace(m, rotations=R))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "LeftForeArm"] == [("frozen", 200, 229)]


def test_two_impossible_jumps_out_and_back_are_a_spike_even_to_a_familiar_pose(walk):
    """The thigh thrown for 3 frames to the pose farthest from it that it takes elsewhere:
    each jump, at 120 Hz, is faster than any hip and swings the foot by decimetres, so out
    and back is a spike though the pose is the leg's own (the pose test is for pops no faster
    than real motion)."""
    j = _joint(walk, "RightUpLeg")
    R = np.array(walk.rotations, copy=True)
    far = 300 + int(np.argmin(np.abs(R[300:, j] @ R[199, j])))
    R[200:203, j] = R[far, j]
    _, report = clean(dataclasses.replace(walk, rotations=R))
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "RightUpLeg"] == [("spike", 200, 202)]


@pytest.mark.parametrize("fps", [30.0, 60.0])
def test_frozen_joint_is_found_at_other_rates(walk, fps):
    """The still threshold is a speed (``still_speed``, degrees per second), not a step per frame."""
    m = walk.resample(fps)
    j = _joint(m, "RightUpLeg")
    s, n = int(round(2.5 * fps)), int(round(0.25 * fps))
    _, report = clean(_with(m, j, list(range(s, s + n)), hold=True))
    mine = [(g.start, g.end) for g in report.glitches if g.joint == "RightUpLeg" and g.kind == "frozen"]
    assert mine == [(s, s + n - 1)]


def test_clean_options_are_validated():
    from physmocap.clean import CleanOptions
    from physmocap.errors import OptionError

    with pytest.raises(OptionError, match="still_speed"):
        CleanOptions(still_speed=-1.0)
    with pytest.raises(OptionError, match="match_windows"):
        CleanOptions(match_windows=1.5)


def test_repair_settings_come_from_the_options(walk):
    """``offset_min_time`` decides between taking a segment's offset off and bridging it."""
    from physmocap.clean import CleanOptions
    from physmocap.clean.correct import blend_shares

    j = _joint(walk, "LeftForeArm")
    frames = list(range(180, 216))  # 0.3 s
    q = Rotation.from_rotvec(np.radians(35.0) * np.array([0.6, 0.0, 0.8])).as_quat()
    bad = _with(walk, j, frames, q)
    _, report = clean(bad, CleanOptions(offset_min_time=1.0, match_windows=1))
    mine = [g for g in report.glitches if g.joint == "LeftForeArm"]
    assert len(mine) == 1 and set(blend_shares(mine[0].corrected)) <= set(BRIDGES)


def test_glitch_at_the_clips_start_holds_the_first_good_rotation(walk):
    """Nothing before the span to bridge from: its first good rotation is held, exactly."""
    from physmocap.clean.correct import correct_glitches
    from physmocap.clean.detect import Glitch

    m = walk.slice_frames(0, 200)
    j = _joint(m, "LeftForeArm")
    R = np.asarray(m.rotations)
    fixed, done = correct_glitches(m, [Glitch("spike", "LeftForeArm", 0, 9, 30.0)])
    assert done[0].corrected == "held"
    assert np.array_equal(np.asarray(fixed.rotations)[:10, j], np.repeat(R[10:11, j], 10, axis=0))


def test_table_shows_metres_to_the_millimetre():
    from physmocap.clean import GlitchReport
    from physmocap.clean.detect import Glitch

    g = Glitch("bone_stretch", "left_hand_end", 4, 8, 0.0091, unit="m")
    assert " 0.009 m " in GlitchReport("x", 10, 120.0, (g,)).table()


@pytest.mark.parametrize("field", ["rotations", "translations"])
def test_a_non_finite_channel_is_refused_naming_joint_and_frame(walk, field):
    """The BVH reader refuses NaN; a motion built in Python is refused by ``clean`` the same
    way (one error naming the frame and joint), not cleaned into a file the writer refuses."""
    from physmocap.errors import InputError

    arr = np.array(getattr(walk, field), copy=True)
    arr[17, 0, 1] = np.nan
    with pytest.raises(InputError, match=r"frame 17: joint '.+' has a non-finite"):
        clean(dataclasses.replace(walk, **{field: arr}))


def test_a_glitch_near_the_clip_start_is_judged_on_two_pseudo_gaps():
    """The bridge's choice (cubic or matched) rests on as much of the joint's own motion near
    the clip's ends as in the middle: where no pseudo-gap fits before the span, two after it."""
    from physmocap.clean.correct import _pseudo_gaps

    assert _pseudo_gaps(100, 109, 500) == [88, 112]  # one each side
    assert _pseudo_gaps(10, 19, 500) == [22, 33]  # none before: two after, one frame apart
    assert _pseudo_gaps(480, 489, 500) == [468, 457]  # none after: two before
    assert _pseudo_gaps(10, 19, 35) == [22]  # room for one only
    assert _pseudo_gaps(2, 30, 40) == []


def test_the_mirror_knows_sides_the_mapping_knows(walk):
    """Before: the mirrored bridge paired left and right joints by name alone, so a skeleton
    named ``mixamorig:LeftUpLeg`` (or ``thigh.L``) got no mirrored estimate; the sides now
    come from the name mapping too (positional.twin_pairs), and CMU's names pair as before."""
    from physmocap.clean.correct import _mirror
    from physmocap.clean.detect import canonical_joints

    sk = walk.skeleton
    names = tuple("mixamorig:" + n for n in sk.names)
    renamed = dataclasses.replace(walk, skeleton=type(sk)(names=names, parents=sk.parents, offsets=sk.offsets,
                                                          end_site=sk.end_site))
    twin, _ = _mirror(renamed, canonical_joints(renamed))
    assert names[twin[names.index("mixamorig:LeftUpLeg")]] == "mixamorig:RightUpLeg"
    assert names[twin[names.index("mixamorig:RightArm")]] == "mixamorig:LeftArm"
    plain, _ = _mirror(walk, canonical_joints(walk))
    by_name, _ = _mirror(walk, {})
    np.testing.assert_array_equal(plain, by_name)


def test_the_mirrored_body_is_scored_without_being_held(walk):
    """The matcher holds one (F, J, 9) array, not a mirrored copy of it as well: the mirrored
    windows' scores come from the plain body and the template reflected, and equal those of
    the mirrored body built out (its glitched pairs left out; a side that does not move, so
    not animated, read from its own rotations)."""
    from scipy.signal import fftconvolve

    from physmocap.clean import CleanOptions
    from physmocap.clean.correct import _matcher
    from physmocap.clean.detect import Glitch, animated_joints, canonical_joints
    from physmocap.rotations import Rotation

    R = np.array(walk.rotations, copy=True)
    R[:, _joint(walk, "LeftToeBase")] = R[0, _joint(walk, "LeftToeBase")]  # still: not animated
    m = dataclasses.replace(walk, rotations=R)
    glitches = [Glitch("frozen", "RightUpLeg", 300, 347, 1.0), Glitch("spike", "LeftToeBase", 280, 282, 1.0),
                Glitch("frozen", "Spine", 500, 530, 1.0)]
    matcher = _matcher(m, glitches, CleanOptions(), canonical_joints(m))
    held = [v for v in vars(matcher).values() if isinstance(v, np.ndarray) and v.shape[-1:] == (9,)]
    assert len(held) == 1  # the plain body's rotation matrices, no mirrored copy
    an = animated_joints(m)
    other = matcher.twin[an]
    assert _joint(m, "LeftToeBase") in other and _joint(m, "LeftToeBase") not in an
    F, A = m.num_frames, len(an)
    body = Rotation.from_quat(R[:, other].reshape(-1, 4)).as_matrix()
    body = (matcher.reflect @ body @ matcher.reflect).reshape(F, A, 9) * ~matcher.bad[:, other][..., None]
    T = matcher.M[250:400] * (~matcher.bad[250:400][:, an])[..., None]
    built = fftconvolve(body.reshape(F, -1), T.reshape(150, -1)[::-1], mode="valid", axes=0).sum(axis=1)
    np.testing.assert_allclose(matcher._mirrored_scores(T), built, rtol=0, atol=1e-12 * np.abs(built).max())


def test_a_blend_is_reported_with_its_shares():
    """The report names every bridge of an average and its share of the weights, the largest
    first, and blend_shares reads it back (a single estimate is all of it)."""
    from physmocap.clean.correct import _blend_name, blend_shares

    name = _blend_name(["cubic", "matched", "mirrored"], np.array([1.0, 2.0, 5.0]))
    assert name == "blend of mirrored 62% + matched 25% + cubic 12%"
    assert blend_shares(name + ", on contact") == {"mirrored": 0.62, "matched": 0.25, "cubic": 0.12}
    assert blend_shares("matched, on contact") == {"matched": 1.0}
    assert blend_shares("blend of among its neighbours 60% + child-relative 40%, on bones") == {
        "among its neighbours": 0.6, "child-relative": 0.4}


def test_the_window_correlation_is_summed_in_blocks_of_joints(monkeypatch):
    """The matcher's correlation sums its channels in the frequency domain a block of joints at
    a time: the same scores (to rounding) as correlating every channel and summing, whatever
    the block."""
    from scipy.signal import fftconvolve

    import physmocap.clean.correct as correct

    rng = np.random.default_rng(3)
    body, T = rng.normal(size=(500, 7, 9)), rng.normal(size=(61, 7, 9))
    T[:, 4] = 0.0  # a joint left out of the template
    whole = fftconvolve(body.reshape(500, -1), T.reshape(61, -1)[::-1], mode="valid", axes=0).sum(axis=1)
    np.testing.assert_allclose(correct._correlation(body, T), whole, rtol=0, atol=1e-10 * np.abs(whole).max())
    monkeypatch.setattr(correct, "CORRELATION_BLOCK_BYTES", 1)  # one joint a block
    np.testing.assert_allclose(correct._correlation(body, T), whole, rtol=0, atol=1e-10 * np.abs(whole).max())


def _benchmark():
    from conftest import load_script

    return load_script("glitch_benchmark")


def test_benchmark_leaves_the_reference_own_glitches_out_of_the_error(walk):
    """A "clean" reference with a glitch of its own (a thigh flipped 180 degrees for 6 frames)
    that every cleaned version repairs: the benchmark's error leaves out exactly the joint
    positions the untouched clip's cleaning moves (the leg below the thigh on those frames),
    so a repair of the reference's own glitch is not scored as error, and the rest of the
    body on those frames still is."""
    bench = _benchmark()
    j = _joint(walk, "RightUpLeg")
    flip = Rotation.from_rotvec([np.pi, 0, 0]).as_quat()
    frames = list(range(200, 206))
    reference = _with(walk, j, frames, q=flip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base_fixed, _ = clean(reference)
    own = bench.own_moved(reference, base_fixed)
    moved_frames = np.flatnonzero(own.any(axis=1))
    assert set(moved_frames) == set(frames)
    below = {k for k in range(len(walk.skeleton.names)) if own[frames[0], k]}
    leg = {k for k in range(len(walk.skeleton.parents)) if _descends(walk.skeleton.parents, k, j)}
    assert below and below <= leg
    # the cleaner's output of the reference itself: no error left on the positions counted,
    # the flipped leg's positions not counted (not scored against the reference's flip)
    P0, Pf = reference.world_positions(), base_fixed.world_positions()
    b, a, n, left = bench.position_errors(P0, Pf, P0, frames, own)
    assert a == 0.0 and left == len(frames) * len(below) and n == len(frames) * (own.shape[1] - len(below))
    b_all, a_all, _, left_all = bench.position_errors(P0, Pf, P0, frames, np.zeros_like(own))
    assert a_all > 0.0 and left_all == 0  # the old figure: the repair of the reference's flip counted as error
    assert np.all(bench.worst_increase(P0, Pf, P0, frames, own) == 0.0)


def _descends(parents, k, j):
    while k >= 0:
        if k == j:
            return True
        k = parents[k]
    return False


def test_knee_frozen_as_it_leaves_its_clamped_extension_is_found_and_repaired(walk):
    """CMU's knees hold full extension (the identity) exactly in every stance, a limit the
    solver clamps to and no freeze.  A right knee frozen for 0.26 s just as it leaves that hold
    (frames 113-143, after its hold of 89-112) holds the limit on and jumps back: the run of the
    limit is longer than any other and ends catching up, so the part past the limit's longest
    other hold is frozen, found on exactly the frozen frames and repaired; the clip's own holds
    stay unflagged."""
    j = _joint(walk, "RightLeg")
    frames = list(range(113, 144))
    bad = _with(walk, j, frames, hold=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fixed, report = clean(bad)
    mine = [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "RightLeg"]
    assert mine == [("frozen", 113, 143)]
    assert not [g for g in clean(walk)[1].glitches if g.kind == "frozen"]
    P0, Pb, Pf = walk.world_positions(), bad.world_positions(), fixed.world_positions()
    before = np.sqrt(np.mean(np.sum((Pb[frames] - P0[frames]) ** 2, axis=-1)))
    after = np.sqrt(np.mean(np.sum((Pf[frames] - P0[frames]) ** 2, axis=-1)))
    assert after < 0.2 * before
    assert np.array_equal(np.asarray(fixed.rotations)[:112], np.asarray(bad.rotations)[:112])  # the hold kept


def test_spike_out_of_a_held_value_is_no_catch_up(walk):
    """The bundled walk's finger holds one value from frame 1 to its end; a 2-frame spike
    (frames 356-357) splits that hold in two runs of the same value, the first ending in a
    jump.  The jump is the spike's (undone two frames later), not a joint catching up after
    a freeze: only the spike is reported."""
    j = _joint(walk, "RightHandIndex1")
    q = Rotation.from_rotvec(np.radians(60.0) * np.array([0.0, 0.6, 0.8])).as_quat()
    bad = _with(walk, j, [356, 357], q=q)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, report = clean(bad)
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "RightHandIndex1"] == [("spike", 356, 357)]


def test_pseudo_gaps_judge_each_estimate_by_the_share_of_the_hold_it_leaves():
    """The dance's right forearm frozen for 50 frames (240-289) as it comes to rest after a
    swing: the pseudo-gap before the span is that 13-degree swing, where only the cubic has
    some skill, and the one after is nearly still, like the span, where the matched and
    regressed motion do best.  Summed as absolute errors the swing outweighs the still gap and
    the cubic, carrying the swing's speed through the span, was chosen (7.5 degrees RMS off,
    worse than the freeze); judged by the share of each pseudo-gap's held-pose error they
    leave, both gaps count and the repair beats the freeze."""
    from conftest import shared_file

    from physmocap.clean.detect import _angle

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = load_motion(shared_file("cmu_05_10_dance_spins.bvh"))
        j = _joint(m, "RightForeArm")
        frames = list(range(240, 290))
        bad = _with(m, j, frames, hold=True)
        fixed, report = clean(bad)
    assert [(g.kind, g.start, g.end) for g in report.glitches if g.joint == "RightForeArm"] == [("frozen", 240, 289)]
    R0 = np.asarray(m.rotations)[frames, j]
    held = np.sqrt(np.mean(_angle(np.asarray(bad.rotations)[frames, j], R0) ** 2))
    after = np.sqrt(np.mean(_angle(np.asarray(fixed.rotations)[frames, j], R0) ** 2))
    assert after < 0.75 * held, (after, held)
