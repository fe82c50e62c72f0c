"""Exports of a retargeted character: BVH (FK must match MuJoCo), NPZ and CSV trajectories."""

from __future__ import annotations

import csv
import shutil
import subprocess

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, retargeted
from physmocap.errors import OutputError
from physmocap.export.character_bvh import write_character_bvh
from physmocap.export.trajectory import write_trajectory_csv, write_trajectory_npz
from physmocap.sources.bvh import read_bvh

pytestmark = RETARGET_DIAGNOSTICS


def _body_ids(traj, names):
    return [traj.model.body(n).id for n in names]


@pytest.mark.parametrize("character", ["humanoid", "robot"])
@pytest.mark.parametrize("up,units", [("Y", "m"), ("Z", "cm")])
def test_bvh_fk_reproduces_mujoco_bodies(tmp_path, character, up, units):
    _, traj = retargeted("cmu_12_01_walk.bvh", character)
    out = tmp_path / "char.bvh"
    write_character_bvh(traj, out, up=up, units=units)
    text = out.read_text()
    assert f"Frames: {traj.num_frames}" in text
    back = read_bvh(out, units=units, up=up)
    assert back.num_frames == traj.num_frames
    assert back.fps == pytest.approx(traj.fps, rel=1e-5)
    joints = [n for n, e in zip(back.skeleton.names, back.skeleton.end_site) if not e]
    pos_bvh = back.world_positions()[:, [back.skeleton.index(n) for n in joints]]
    pos_mj, _ = traj.body_poses()
    pos_mj = pos_mj[:, _body_ids(traj, joints)]
    err = np.linalg.norm(pos_bvh - pos_mj, axis=-1)
    assert err.max() < 1e-3, f"max {err.max() * 1000:.3f} mm"


def test_bvh_channels_are_joint_angles_for_the_humanoid(tmp_path):
    _, traj = retargeted("cmu_12_01_walk.bvh", "humanoid")
    out = tmp_path / "h.bvh"
    write_character_bvh(traj, out, up="Z")
    back = read_bvh(out, up="Z", units="m")
    # with Z up, a knee's single hinge about -Y... appears as its Y channel: compare magnitudes
    chans = back.meta["bvh_channels"]
    assert chans["pelvis"][:3] == ["Xposition", "Yposition", "Zposition"]
    knee = traj.model.joint("left_knee_flexion")
    q = traj.qpos[:, knee.qposadr[0]]
    from physmocap.rotations import quat_to_euler

    order = "".join(c[0] for c in chans["left_shank"] if c.endswith("rotation")) if "left_shank" in chans else None
    if order is None:
        pytest.skip("humanoid shank body has another name")
    eul = quat_to_euler(back.rotations[:, back.skeleton.index("left_shank")], order)
    assert np.allclose(np.abs(eul[:, 0]), np.abs(q), atol=1e-5)


def test_npz_and_csv_trajectories(tmp_path):
    _, traj = retargeted("cmu_12_01_walk.bvh", "humanoid")
    npz = write_trajectory_npz(traj, tmp_path / "t.npz")
    with np.load(npz, allow_pickle=False) as z:
        assert z["qpos"].shape == traj.qpos.shape
        np.testing.assert_array_equal(z["qpos"], traj.qpos)
        assert z["qvel"].shape == (traj.num_frames, traj.model.nv)
        assert float(z["fps"]) == pytest.approx(traj.fps)
        assert str(z["quat_convention"]) == "wxyz"
        assert list(z["qpos_names"][:7]) == ["root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz"]
        assert str(z["mjcf_path"]) == "humanoid"
    path = write_trajectory_csv(traj, tmp_path / "t.csv")
    rows = list(csv.reader(path.open()))
    assert rows[0][:3] == ["frame", "time", "root_x"]
    assert len(rows) == traj.num_frames + 1
    vals = np.array(rows[1:], dtype=float)[:, 2:]
    np.testing.assert_allclose(vals, traj.qpos, atol=1e-7)


def test_non_finite_trajectory_is_refused_without_a_file(tmp_path):
    _, traj = retargeted("cmu_12_01_walk.bvh", "humanoid")
    from physmocap.trajectory import Trajectory

    bad = Trajectory(traj.character, traj.qpos.copy(), traj.fps)
    bad.qpos[3, 9] = np.nan
    for fn, name in ((write_trajectory_npz, "x.npz"), (write_trajectory_csv, "x.csv")):
        with pytest.raises(OutputError, match="frame 3"):
            fn(bad, tmp_path / name)
        assert not (tmp_path / name).exists()
    assert list(tmp_path.iterdir()) == []


BLENDER_SCRIPT = r"""
import builtins, bpy, json, sys
# Debian's Blender 3.4 BVH add-on opens files with mode "rU", which its Python 3.11 rejects.
_open = builtins.open
builtins.open = lambda f, mode="r", *a, **k: _open(f, mode.replace("U", ""), *a, **k)
argv = sys.argv[sys.argv.index("--") + 1:]
bvh, out, frames = argv[0], argv[1], int(argv[2])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath=bvh, axis_forward="-Z", axis_up="Y", global_scale=1.0,
                        rotate_mode="NATIVE", use_fps_scale=False, update_scene_fps=False,
                        update_scene_duration=True)
arm = bpy.context.object
scene = bpy.context.scene
res = {}
for f in range(frames):
    scene.frame_set(scene.frame_start + f)
    res[f] = {b.name: list(arm.matrix_world @ b.head) for b in arm.pose.bones}
json.dump(res, open(out, "w"))
"""


@pytest.mark.skipif(shutil.which("blender") is None, reason="Blender is not installed (apt-get install blender)")
@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_blender_importer_agrees_with_mujoco(tmp_path, character):
    import json

    _, traj = retargeted("cmu_12_01_walk.bvh", character)
    from physmocap.trajectory import Trajectory

    n = 40
    short = Trajectory(traj.character, traj.qpos[::10][:n], traj.fps / 10)
    bvh = tmp_path / "c.bvh"
    write_character_bvh(short, bvh, up="Y", units="m")
    script = tmp_path / "dump.py"
    script.write_text(BLENDER_SCRIPT)
    out = tmp_path / "pos.json"
    subprocess.run(
        ["blender", "-b", "--factory-startup", "--python", str(script), "--", str(bvh), str(out), str(n)],
        check=True, capture_output=True, timeout=300,
    )
    res = json.loads(out.read_text())
    pos_mj, _ = short.body_poses()
    worst = 0.0
    for f in range(n):
        for name, head in res[str(f)].items():
            # Blender imports Y-up as Z-up with forward -Z -> -Y... i.e. the same Z-up world as MuJoCo
            p = np.array(head)
            worst = max(worst, float(np.linalg.norm(p - pos_mj[f, traj.model.body(name).id])))
    assert worst < 1e-3, f"Blender's pose differs from MuJoCo's by {worst * 1000:.3f} mm"
