"""Glitch detection and repair (issue 12, first part) on the bundled walk with injected glitches."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from physmocap.cli import main
from physmocap.clean import clean
from physmocap.rotations import Rotation, quat_mul
from physmocap.sources import load_motion


@pytest.fixture(scope="module")
def walk():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_motion("example")


def _joint(m, name):
    return m.skeleton.names.index(name)


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
    assert mine[0].corrected == "slerp"
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
