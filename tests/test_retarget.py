"""Retargeting acceptance (issue 4) on the real shared BVH clips, onto both bundled characters."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, SHARED_BVH, WALKS, retargeted
from physmocap import metrics

pytestmark = RETARGET_DIAGNOSTICS

CHARACTERS = ["humanoid", "robot"]
CASES = [(clip, ch) for clip in SHARED_BVH for ch in CHARACTERS]


@pytest.mark.parametrize("clip,character", CASES)
def test_hard_constraints_hold_on_every_frame(clip, character):
    motion, traj = retargeted(clip, character)
    model = traj.model
    # never drops a frame (a reference pose at frame 0 is skipped on purpose, and said so)
    assert traj.num_frames == motion.num_frames - traj.source_start
    assert np.all(np.isfinite(traj.qpos))
    lim = metrics.joint_limit_violations(model, traj.qpos)
    assert lim["count"] == 0, lim
    ch = traj.character
    vel = metrics.velocity_violations(model, traj.qpos, traj.fps, ch.velocity_limits, groups=ch.velocity_groups)
    assert vel["count"] == 0, vel
    low = metrics.lowest_heights(model, traj.qpos)
    assert low.min() > -1e-3, f"a geom is {-low.min() * 1000:.2f} mm below the floor on frame {int(np.argmin(low))}"


@pytest.mark.parametrize("clip,character", [(c, ch) for c in WALKS for ch in CHARACTERS])
def test_walks_track_limbs_within_3cm(clip, character):
    """Ankles, knees, wrists and elbows within 3 cm of their targets (feet outside stance)."""
    _, traj = retargeted(clip, character)
    tracking = metrics.tracking_errors(traj, metrics.outside_stance_mask(traj))
    assert tracking["key_joints_mean_cm"] < 3.0, tracking["position_cm"]


@pytest.mark.parametrize("character", CHARACTERS)
def test_every_tracked_joint_has_targets(character):
    _, traj = retargeted("cmu_12_01_walk.bvh", character)
    names = set(traj.targets.names)
    for j in ("pelvis", "left_knee", "right_ankle", "left_elbow", "right_wrist"):
        assert j in names


def test_result_is_deterministic(tmp_path):
    from physmocap.export.character_bvh import write_character_bvh
    from physmocap.export.trajectory import write_trajectory_npz
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    motion = load_motion("example").slice_frames(0, 60)
    outs = []
    for k in range(2):
        traj = retarget(motion, load_character(), progress=False)
        write_character_bvh(traj, tmp_path / f"a{k}.bvh")
        write_trajectory_npz(traj, tmp_path / f"a{k}.npz")
        outs.append(((tmp_path / f"a{k}.bvh").read_bytes(), (tmp_path / f"a{k}.npz").read_bytes()))
    assert outs[0] == outs[1]


@pytest.mark.parametrize("character", CHARACTERS)
def test_garbage_motion_still_respects_every_hard_constraint(character):
    """Random, jumpy joint rotations and a teleporting root: the output stays finite,
    inside the joint and velocity limits, above the floor, and keeps every frame."""
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.motion import Motion
    from physmocap.rotations import Rotation, quat_mul
    from physmocap.sources import load_motion

    walk = load_motion("example").slice_frames(1, 61)
    rng = np.random.default_rng(7)
    F, J = walk.rotations.shape[:2]
    noise = Rotation.from_rotvec(rng.normal(scale=0.8, size=(F * J, 3))).as_quat().reshape(F, J, 4)
    rot = quat_mul(walk.rotations, noise)
    tra = walk.translations + rng.normal(scale=0.3, size=walk.translations.shape)
    bad = Motion(walk.skeleton, walk.fps, rotations=rot, translations=tra, translated=walk.translated)
    ch = load_character(character)
    traj = retarget(bad, ch, progress=False)
    assert traj.num_frames == F and np.all(np.isfinite(traj.qpos))
    assert metrics.joint_limit_violations(ch.model, traj.qpos)["count"] == 0
    assert metrics.velocity_violations(ch.model, traj.qpos, traj.fps, ch.velocity_limits, groups=ch.velocity_groups)["count"] == 0
    assert metrics.lowest_heights(ch.model, traj.qpos).min() > -1e-3
