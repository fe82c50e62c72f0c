"""The regressed bridges (physmocap/clean/regress.py): a bridged joint's motion regressed on
the rest of the body, learned from the clip itself."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from physmocap.clean import CleanOptions
from physmocap.clean.detect import Glitch, canonical_joints
from physmocap.rotations import Rotation, quat_mul
from physmocap.sources import load_motion


@pytest.fixture(scope="module")
def walk():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_motion("example")


def _span_rms(m, reference, frames) -> float:
    P, P0 = m.world_positions()[frames], reference.world_positions()[frames]
    return float(np.sqrt(np.mean(np.sum((P - P0) ** 2, axis=-1))))


def _bridged(m, j, frames, q):
    """``m`` with joint ``j``'s rotations on ``frames`` replaced by ``q``."""
    R = np.array(m.rotations, copy=True)
    R[frames, j] = q
    return dataclasses.replace(m, rotations=R)


def _coupled(walk):
    """The walk with its left forearm turning with the right knee (its rotation the knee's
    about another axis, an offset on top): a joint the rest of the body predicts exactly,
    whose motion is no curve between its ends and, the knee's stride varying, no copy of
    another stride either."""
    R = np.array(walk.rotations, copy=True)
    names = walk.skeleton.names
    j, k = names.index("LeftForeArm"), names.index("RightLeg")
    swap = Rotation.from_euler("z", 90, degrees=True)
    R[:, j] = quat_mul(Rotation.from_euler("x", 20, degrees=True).as_quat(),
                       (swap * Rotation.from_quat(R[:, k]) * swap.inv()).as_quat())
    return dataclasses.replace(walk, rotations=R), j


def test_a_joint_the_body_predicts_is_bridged_by_the_regression(walk):
    """Frozen for 0.4 s, the coupled forearm is rebuilt by the regression on the other joints
    (its pose a linear function of the knee's rotation matrix) to within a fraction of what
    the cubic, matched and mirrored bridges leave, and the report names it.  Before the
    regression the best bridge left several times the error."""
    from physmocap.clean.correct import _hermite, _matcher, correct_glitches

    clip, j = _coupled(walk)
    frames = list(range(300, 348))
    R = np.array(clip.rotations, copy=True)
    R[frames, j] = R[299, j]
    bad = dataclasses.replace(clip, rotations=R)
    glitch = [Glitch("frozen", "LeftForeArm", 300, 347, 1.0)]
    matcher = _matcher(bad, glitch, CleanOptions(), canonical_joints(bad))
    old = [_hermite(R[:, j], 299, 348), matcher.bridge(j, 300, 347), matcher.bridge(j, 300, 347, None, True)]
    best_old = min(_span_rms(_bridged(bad, j, frames, q), clip, frames) for q in old)
    fixed, done = correct_glitches(bad, glitch, CleanOptions(contact_height=1e-6))
    assert done[0].corrected.split(",")[0].replace("blend of ", "").startswith("regressed"), done[0].corrected
    after = _span_rms(fixed, clip, frames)
    assert after < 0.2 * best_old and after < 0.02 * _span_rms(bad, clip, frames), (after, best_old)
    untouched = np.ones(len(R), bool)
    untouched[frames] = False
    assert np.array_equal(fixed.rotations[untouched], bad.rotations[untouched])


def test_leaving_frames_out_of_the_fit_equals_fitting_without_them(walk, monkeypatch):
    """The fit is held as sums; a pseudo-gap is left out by taking its frames' terms off, and
    the sums are accumulated a block of frames at a time: the predictions equal a ridge
    regression fitted from scratch on the remaining frames, whatever the block."""
    import physmocap.clean.regress as regress
    from physmocap.clean.correct import _matcher

    glitch = [Glitch("frozen", "RightLeg", 300, 347, 1.0)]
    matcher = _matcher(walk, glitch, CleanOptions(), canonical_joints(walk))
    R = np.asarray(walk.rotations, dtype=float)
    j = walk.skeleton.names.index("RightLeg")
    left_out = np.arange(240, 300)
    at = np.arange(250, 260)
    ridges = [0.001, 0.1]
    got = regress.Regression(R, matcher.M, matcher.animated, matcher.bad, j, 300, 347, 0.01)._predict(left_out, at, ridges)
    monkeypatch.setattr(regress, "BLOCK_FRAMES", 7)
    reg = regress.Regression(R, matcher.M, matcher.animated, matcher.bad, j, 300, 347, 0.01)
    blocked = reg._predict(left_out, at, ridges)
    train = reg.usable.copy()
    train[left_out] = False
    t = np.flatnonzero(train)
    X, Y = reg._features(t), reg._targets(t)
    mu, sd = X.mean(axis=0), X.std(axis=0) + regress._EPS
    Z = (X - mu) / sd
    for lam, a, b in zip(ridges, got, blocked):
        W = np.linalg.solve(Z.T @ Z + lam * len(t) * np.eye(Z.shape[1]), Z.T @ (Y - Y.mean(axis=0)))
        direct = ((reg._features(at) - mu) / sd) @ W + Y.mean(axis=0)
        np.testing.assert_allclose(a, direct, atol=1e-6)
        np.testing.assert_allclose(b, direct, atol=1e-6)


def test_regressed_bridges_join_both_ends(walk):
    """Both estimates start from the last good rotation and arrive at the first good one: the
    pose's mismatch at both ends is faded out across the span, the steps' at the far end
    spread over it, so neither leaves a jump at the span's ends (no step there larger than the
    joint's own largest step inside the rebuilt frames plus its motion next to them)."""
    from physmocap.clean.correct import _matcher
    from physmocap.clean.detect import _angle
    from physmocap.clean.regress import Regression

    glitch = [Glitch("frozen", "LeftUpLeg", 300, 347, 1.0)]
    matcher = _matcher(walk, glitch, CleanOptions(), canonical_joints(walk))
    R = np.asarray(walk.rotations, dtype=float)
    j = walk.skeleton.names.index("LeftUpLeg")
    reg = Regression(R, matcher.M, matcher.animated, matcher.bad, j, 300, 347, 0.01)
    for est in reg.estimates(300, 347):
        path = np.concatenate([R[299:300, j], est, R[348:349, j]])
        steps = _angle(path[1:], path[:-1])
        own = _angle(R[300:349, j], R[299:348, j]).max()
        assert steps[0] <= 2 * own and steps[-1] <= 2 * own, (steps[0], steps[-1], own)
