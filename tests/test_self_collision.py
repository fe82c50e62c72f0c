"""Issue 13: the limbs do not pass through each other or the trunk."""

from __future__ import annotations

import numpy as np
import pytest

import physmocap
from physmocap.metrics import self_penetration
from physmocap.models import load_character
from physmocap.models.selfcollision import limb_groups, self_collision_pairs
from conftest import RETARGET_DIAGNOSTICS

pytestmark = RETARGET_DIAGNOSTICS


@pytest.fixture(scope="module")
def walk():
    return physmocap.load_motion("example").slice_frames(1, 241)


@pytest.mark.parametrize("name", [None, "robot"])
def test_limb_groups_come_from_the_mapping(name):
    ch = load_character(name)
    groups = limb_groups(ch)
    assert set(groups) == {"left_leg", "right_leg", "left_arm", "right_arm", "trunk"}
    model = ch.model
    knee = int(model.site_bodyid[ch.frame_id("left_knee")])
    elbow = int(model.site_bodyid[ch.frame_id("right_elbow")])
    assert knee in groups["left_leg"] and elbow in groups["right_arm"]
    assert all(not (groups[a] & groups[b]) for a in groups for b in groups if a < b)  # a partition
    pairs = self_collision_pairs(ch)
    assert pairs == sorted(set(pairs)) and all(g1 < g2 for g1, g2 in pairs)


@pytest.mark.parametrize("name", [None, "robot"])
def test_walk_keeps_limbs_apart(walk, name):
    """Before: the humanoid's shanks overlapped by up to 6.6 cm on the CMU walk, the robot's
    arms went 5 cm into its thighs on half of the frames."""
    ch = load_character(name)
    free = physmocap.retarget(walk, ch, start=0, progress=False, self_collision=False)
    kept = physmocap.retarget(walk, ch, start=0, progress=False)
    before, after = self_penetration(ch, free.qpos), self_penetration(ch, kept.qpos)
    assert before["max_mm"] > 10.0
    assert after["max_mm"] < 5.0 and after["share_over_2mm"] < 0.02, after
    assert kept.fidelity.worst_segment_median_deg < free.fidelity.worst_segment_median_deg + 1.0
    assert np.all(kept.solver.relaxation < 3)


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_no_self_penetration_deeper_than_5mm_on_the_shared_clips(character):
    """Issue 13's acceptance, on every shared BVH (retargets shared with the planting tests)."""
    from conftest import SHARED_BVH, retargeted, shared_file

    if not SHARED_BVH:
        shared_file("cmu_12_01_walk.bvh")  # skips with a message when ../shared is absent
    for clip in SHARED_BVH:
        _, traj = retargeted(clip, character)
        sp = self_penetration(traj.character, traj.qpos)
        assert sp["max_mm"] < 5.0, (clip, sp)
