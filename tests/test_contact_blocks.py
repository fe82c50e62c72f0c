"""Contact detection and the fidelity figures read the actor's world positions in blocks of frames,
only the joints they need (Motion.joint_world_positions)."""

from __future__ import annotations

import numpy as np

from conftest import shared_file


def test_joint_world_positions_match_the_whole_clip() -> None:
    from physmocap.sources import load_motion

    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    joints = [5, 2, 7, 2]
    world, column = motion.joint_world_positions(joints, block=97)  # several blocks, the last one short
    assert world.shape == (motion.num_frames, 3, 3)
    full = motion.world_positions()
    for j in joints:
        assert np.array_equal(world[:, column[j]], full[:, j])


def test_positional_motion_is_not_copied() -> None:
    from physmocap.sources import load_motion

    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    positional = motion.replace(positions=motion.world_positions(), rotations=None, translations=None)
    world, column = positional.joint_world_positions([3, 1])
    assert world is positional.positions and column == {3: 3, 1: 1}


def test_floor_height_in_blocks_is_the_whole_clips(monkeypatch) -> None:
    import physmocap.motion as motion_module
    from physmocap.sources import load_motion

    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    whole = float(np.percentile(motion.world_positions()[..., 2].min(axis=1), 5.0))
    monkeypatch.setattr(motion_module, "WORLD_BLOCK_FRAMES", 97)  # several blocks, the last one short
    assert motion.floor_height() == whole
