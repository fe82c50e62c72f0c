"""Toe tips given back to skeletons whose toe end sites have no length (Bandai Namco, LAFAN1)."""

from __future__ import annotations

import numpy as np

from physmocap.ik.toetips import extend_toe_tips
from physmocap.motion import Motion, Skeleton

REST = {  # a character's foot: 13 cm ankle to toe joint, 6.5 cm toe to tip (ratio 0.5)
    f"{s}_{j}": p
    for s in ("left", "right")
    for j, p in (("ankle", np.array([0.0, 0.0, 0.07])), ("toe", np.array([0.12, 0.0, 0.02])), ("toe_end", np.array([0.185, 0.0, 0.02])))
}


def _motion(tip_offset: float) -> tuple[Motion, dict[str, int]]:
    names = ("hips", "ankle_l", "toe_l", "toe_l_End")
    offsets = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, -0.9], [0.0, 0.2, -0.05], [0.0, tip_offset, 0.0]])
    sk = Skeleton(names=names, parents=np.array([-1, 0, 1, 2]), offsets=offsets, end_site=np.array([False, False, False, True]))
    F = 3
    rot = np.zeros((F, 4, 4))
    rot[..., 3] = 1.0
    m = Motion(skeleton=sk, fps=30.0, rotations=rot, translations=np.zeros((F, 1, 3)), translated=np.array([0]))
    return m, {"pelvis": 0, "left_ankle": 1, "left_toe": 2}


def test_a_zero_length_toe_end_continues_the_foot_bone():
    motion, idx = _motion(0.0)
    before = motion.skeleton.offsets.copy()
    out, out_idx = extend_toe_tips(motion, idx, REST)
    assert np.array_equal(motion.skeleton.offsets, before) and "left_toe_end" not in idx  # inputs untouched
    assert out_idx["left_toe_end"] == 3 and "right_toe_end" not in out_idx
    foot = motion.skeleton.offsets[2]
    ratio = np.linalg.norm(REST["left_toe_end"] - REST["left_toe"]) / np.linalg.norm(REST["left_toe"] - REST["left_ankle"])
    assert np.allclose(out.skeleton.offsets[3], foot * ratio)
    pos = out.world_positions()
    assert np.allclose(pos[:, 3] - pos[:, 2], foot * ratio)


def test_a_toe_end_with_a_length_is_left_alone():
    motion, idx = _motion(0.04)
    idx = {**idx, "left_toe_end": 3}
    out, out_idx = extend_toe_tips(motion, idx, REST)
    assert out is motion and out_idx == idx
