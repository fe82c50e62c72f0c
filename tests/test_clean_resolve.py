"""Repairs re-solved through the hard-limited IK on an actor-fitted humanoid (issue 12, correction:
"corrected poses respect the ranges of motion"), on synthetic glitches whose interpolation
leaves the range of motion: a knee that straightens fast into a glitch and bends fast out of
it, so the cubic bridge overshoots into hyperextension while the real knee stayed locked."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from conftest import shared_file

from physmocap.clean import clean
from physmocap.clean.anatomy import bend_past_range, motion_angles
from physmocap.clean.correct import BRIDGES, blend_shares, correct_glitches
from physmocap.clean.detect import Glitch, canonical_joints
from physmocap.clean.options import CleanOptions
from physmocap.clean.resolve import actor_ik, beyond_range_mask
from physmocap.errors import OptionError
from physmocap.sources import load_motion

SPAN = 12  # frames of the glitch


def _load(name: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_motion(name if name == "example" else shared_file(name))


def _locked_knee(motion, s: int, e: int, side: str = "left"):
    """``(clean, glitched, knee joint)``: ``motion`` with its knee at 2 degrees of flexion
    on ``s - 1 .. e + 1``, straightening into it and bending out of it at 8 degrees per
    frame (10 frames each side), and the span ``s..e`` replaced by a 90-degree twist."""
    R = np.array(motion.rotations, copy=True)
    a, b = s - 1, e + 1
    j = None
    for t in range(a - 10, b + 11):
        d = a - t if t <= a else t - b if t >= b else 0
        lo = -10.0  # the knee's hyperextension stop (models/rom.py): the angle is lo - excess
        j, q = bend_past_range(dataclasses.replace(motion, rotations=R), f"{side}_knee", [t], lo - (2.0 + 8.0 * d))
        R[t, j] = q[0]
    good = dataclasses.replace(motion, rotations=R)
    G = R.copy()
    G[s : e + 1, j] = [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]
    return good, dataclasses.replace(motion, rotations=G), j


def _span_error(motion, reference, s: int, e: int) -> float:
    """Joint-position RMS error (metres, all joints) of ``motion`` on frames ``s..e``."""
    P, P0 = motion.world_positions()[s : e + 1], reference.world_positions()[s : e + 1]
    return float(np.sqrt(np.mean(np.sum((P - P0) ** 2, axis=-1))))


def _check_resolved(motion, s: int) -> None:
    e = s + SPAN - 1
    good, bad, j = _locked_knee(motion, s, e)
    glitch = [Glitch("frozen", motion.skeleton.names[j], s, e, 90.0)]  # bridged at every rate
    ji = canonical_joints(motion)
    single = CleanOptions(blend_ratio=1.0)  # the best bridge alone (a blend with the matched motion overshoots less)
    never, done_never = correct_glitches(bad, glitch, single, resolve="never")
    fixed, done = correct_glitches(bad, glitch, single)
    assert done_never[0].corrected.split(",")[0] in BRIDGES  # blend_ratio 1: one bridge
    assert beyond_range_mask(never, CleanOptions(), ji)[s : e + 1, j].sum() >= SPAN // 2  # the curve overshoots
    assert done[0].corrected == "re-solved"
    assert not beyond_range_mask(fixed, CleanOptions(), ji)[s : e + 1, j].any()
    knee = motion_angles(fixed, ji)[0]["left_knee_flexion"][s : e + 1]
    assert knee.min() > -10.0 - 1e-6
    assert _span_error(fixed, good, s, e) < 0.25 * _span_error(never, good, s, e)
    # only the glitched joint on the glitched frames changes
    R, B = np.asarray(fixed.rotations), np.asarray(bad.rotations)
    outside = np.ones(R.shape[:2], bool)
    outside[s : e + 1, j] = False
    assert np.array_equal(R[outside], B[outside])


def test_interpolation_beyond_the_range_is_re_solved():
    _check_resolved(_load("example"), 200)


RIGS = ["cmu_12_01_walk.bvh", "pymo_walk.bvh", "bandai_walk.bvh", "optitrack_hops_crouch.bvh", "cmu_05_10_dance_spins.bvh"]


@pytest.mark.parametrize("clip", RIGS)
def test_interpolation_beyond_the_range_is_re_solved_on_shared_rigs(clip):
    motion = _load(clip)
    _check_resolved(motion, motion.num_frames // 2)


def _twisted(walk, joint: str, s: int, e: int):
    """``(walk with joint's rotation replaced by a 90-degree twist on s..e, the spike glitch)``."""
    R = np.array(walk.rotations, copy=True)
    R[s : e + 1, walk.skeleton.names.index(joint)] = [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]
    return dataclasses.replace(walk, rotations=R), [Glitch("spike", joint, s, e, 90.0)]


def test_interpolation_within_the_range_is_kept():
    bad, glitch = _twisted(_load("example"), "LeftForeArm", 200, 205)
    never, _ = correct_glitches(bad, glitch, resolve="never")
    fixed, done = correct_glitches(bad, glitch)
    assert set(blend_shares(done[0].corrected)) <= set(BRIDGES)
    assert np.array_equal(np.asarray(fixed.rotations), np.asarray(never.rotations))


def test_always_re_solves_close_to_the_clean_motion():
    """The IK itself (no choice): a spike of the knee re-solved lands within 2 cm of the clean pose."""
    walk = _load("example")
    bad, glitch = _twisted(walk, "LeftLeg", 300, 305)
    fixed, done = correct_glitches(bad, glitch, resolve="always")
    assert done[0].corrected == "re-solved"
    assert _span_error(fixed, walk, 300, 305) < 0.02
    again, _ = correct_glitches(bad, glitch, resolve="always")
    assert np.array_equal(np.asarray(again.rotations), np.asarray(fixed.rotations))  # deterministic


def test_actor_fits_the_mapped_joints():
    walk = _load("example")
    actor = actor_ik(walk, canonical_joints(walk))
    names = walk.skeleton.names
    assert {"LeftLeg", "RightLeg", "LeftForeArm", "LeftUpLeg", "Hips"} <= {names[j] for j in actor.body_of}
    assert not actor.can_resolve(names.index("LeftFingerBase"))


def test_unknown_resolve_mode_is_refused():
    walk = _load("example")
    with pytest.raises(OptionError, match="resolve must be one of never, limits, always"):
        correct_glitches(walk, [], resolve="sometimes")


def test_clean_keeps_an_unglitched_clip_unchanged():
    walk = _load("example")
    fixed, report = clean(walk)
    changed = {t for g in report.glitches if g.corrected for t in range(g.start, g.end + 1)}
    keep = np.setdiff1d(np.arange(walk.num_frames), sorted(changed))
    assert np.array_equal(np.asarray(fixed.rotations)[keep], np.asarray(walk.rotations)[keep])


def test_benchmark_compares_interpolation_and_ik():
    """scripts/glitch_benchmark.py's repair comparison on the bundled walk's injected frozen
    joints: the per-glitch oracle is never worse than interpolation alone or the IK alone."""
    from conftest import load_script

    bench = load_script("glitch_benchmark")
    walk = _load("example")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        glitched, truth, _ = bench.inject(walk, np.random.default_rng([7, 3]), 3, ("frozen",))
        fixed, report = clean(glitched)
    frames = sorted({f for _, f in truth["frozen"]})
    got = bench._method_errors(glitched, fixed, report, walk.world_positions(), frames, np.zeros(walk.num_frames, bool))
    assert set(got) == set(bench.METHODS)
    assert all(v[3] == got["never"][3] > 0 for v in got.values())  # the same repaired glitches
    assert got["oracle"][0] <= min(got["never"][0], got["always"][0]) + 1e-12


def test_clean_command_takes_the_resolve_mode(tmp_path, capsys):
    from physmocap.cli import main

    out = tmp_path / "walk.bvh"
    assert main(["clean", "example", "-o", str(out), "--resolve", "always"]) == 0
    assert out.exists()
    with pytest.raises(SystemExit):
        main(["clean", "example", "--resolve", "sometimes"])
    assert "invalid choice" in capsys.readouterr().err
