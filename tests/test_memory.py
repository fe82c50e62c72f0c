"""Bounded memory (issue 14): the block-by-block paths give exactly what one pass over the clip gives."""

from __future__ import annotations

import numpy as np
import pytest

import physmocap.export.character_bvh as character_bvh
import physmocap.export.trajectory as export_trajectory
import physmocap.motion as motion_mod
from physmocap.models import load_character
from physmocap.resources import resolve_input
from physmocap.sources.bvh import read_bvh
from physmocap.trajectory import Trajectory


@pytest.fixture(scope="module")
def clip():
    return read_bvh(resolve_input("example")).slice_frames(0, 60)


@pytest.fixture(scope="module")
def traj():
    ch = load_character(None)
    rng = np.random.default_rng(0)
    F = 45
    qpos = np.tile(ch.model.qpos0, (F, 1))
    qpos[:, 7:] += 0.2 * np.sin(np.linspace(0.0, 3.0, F))[:, None] * rng.uniform(-1, 1, ch.model.nq - 7)
    qpos[:, :3] += np.linspace(0.0, 1.0, F)[:, None] * np.array([1.0, 0.2, 0.0])
    return Trajectory(character=ch, qpos=qpos, fps=30.0)


def test_forward_kinematics_in_chunks_is_exact(clip, monkeypatch):
    whole = clip.forward_kinematics()
    monkeypatch.setattr(motion_mod, "FK_CHUNK_FRAMES", 7)
    pos, rot = clip.forward_kinematics()
    assert np.array_equal(pos, whole[0]) and np.array_equal(rot, whole[1])
    assert np.array_equal(clip.world_positions(), whole[0])
    small = clip.replace(rotations=clip.rotations.astype(np.float32), translations=clip.translations.astype(np.float32))
    assert small.world_positions().dtype == np.float64


def test_npz_written_block_by_block_has_the_same_bytes(traj, tmp_path, monkeypatch):
    export_trajectory.write_trajectory_npz(traj, tmp_path / "a.npz")
    monkeypatch.setattr(export_trajectory, "BLOCK_ROWS", 4)
    export_trajectory.write_trajectory_npz(traj, tmp_path / "b.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    with np.load(tmp_path / "b.npz", allow_pickle=False) as z:
        assert np.array_equal(z["qpos"], traj.qpos)
        assert np.array_equal(z["qvel"], export_trajectory.qvel_from_qpos(traj.model, traj.qpos, traj.fps))
        assert z["qvel"].shape == (traj.num_frames, traj.model.nv) and not z["qvel"][0].any()
        assert str(z["quat_convention"]) == "wxyz" and float(z["fps"]) == 30.0


def test_npz_member_bytes_are_numpys(tmp_path):
    arrays = {"a": np.arange(12.0).reshape(4, 3), "s": np.array(["x", "yz"]), "n": np.float64(2.5), "e": np.zeros((0, 2))}
    export_trajectory.write_npz(tmp_path / "x.npz", arrays)
    import io
    import zipfile

    with zipfile.ZipFile(tmp_path / "x.npz") as zf:
        for name, value in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(value), allow_pickle=False)
            assert zf.read(f"{name}.npy") == buf.getvalue()


def test_character_motion_in_blocks_is_exact(traj, monkeypatch):
    whole = character_bvh.character_motion(traj)
    monkeypatch.setattr(character_bvh, "BLOCK_FRAMES", 4)
    blocks = character_bvh.character_motion(traj)
    assert np.array_equal(blocks.rotations, whole.rotations)
    assert np.array_equal(blocks.translations, whole.translations)
