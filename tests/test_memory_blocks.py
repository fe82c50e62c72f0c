"""Bounded memory (issue 14, second pass): what is now computed a block of frames at a time
gives exactly, bit for bit and in the same memory layout, what one pass over the clip gives."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import physmocap.export.bvh as bvh_mod
import physmocap.ik.targets as targets_mod
import physmocap.metrics.fidelity as fidelity_mod
from physmocap.errors import OptionError, OutputError
from physmocap.models.geometry import foot_bodies
from physmocap.export.character_bvh import character_motion, write_character_bvh
from physmocap.ik.config import RetargetConfig
from physmocap.ik.footlevel import level_feet
from physmocap.ik.retarget import level_targets, map_motion, resolve_contacts, retarget
from physmocap.ik.targets import build_targets, character_rest_frames
from physmocap.models import load_character
from physmocap.resources import resolve_input
from physmocap.sources.bvh import read_bvh
from physmocap.trajectory import Trajectory


@pytest.fixture(scope="module")
def walk():
    """The bundled CMU walk (its first 150 frames), its canonical joints and its contacts."""
    motion = read_bvh(resolve_input("example")).slice_frames(1, 151)
    joints = map_motion(motion)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        contacts = resolve_contacts(motion, joints, None, RetargetConfig())
    return motion, joints, contacts


@pytest.fixture(scope="module")
def humanoid():
    return load_character(None)


@pytest.fixture(scope="module")
def traj(walk, humanoid):
    motion, _, _ = walk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return retarget(motion, humanoid, progress=False, start=0, max_iterations=2)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal values, dtype and memory layout (the NPZ writer records the layout)."""
    return (a.dtype == b.dtype and np.array_equal(a, b) and a.strides == b.strides
            and a.flags.c_contiguous == b.flags.c_contiguous and a.flags.f_contiguous == b.flags.f_contiguous)


def test_targets_built_from_blocks_of_kinematics_are_exact(walk, humanoid, monkeypatch):
    motion, joints, contacts = walk
    whole = build_targets(motion, joints, humanoid, floor=contacts.floor)
    monkeypatch.setattr(targets_mod, "BLOCK_FRAMES", 7)
    blocks = build_targets(motion, joints, humanoid, floor=contacts.floor)
    for name in ("positions", "orientations", "valid", "source_positions"):
        assert _same(getattr(blocks, name), getattr(whole, name)), name
    assert blocks.calibration.pose_rotations.keys() == whole.calibration.pose_rotations.keys()
    for c, q in whole.calibration.pose_rotations.items():
        assert np.array_equal(blocks.calibration.pose_rotations[c], q), c


def test_targets_built_in_temporary_files_are_exact(walk, humanoid, monkeypatch):
    """Every array of build_targets spilled (the actor's positions, the orientation columns,
    the positions placed joint by joint) and tiny blocks: the same targets, C-ordered."""
    import physmocap.spill as spill_mod
    from physmocap.spill import is_spilled

    motion, joints, contacts = walk
    held = build_targets(motion, joints, humanoid, floor=contacts.floor)
    monkeypatch.setattr(spill_mod, "SPILL_BYTES", 1)
    monkeypatch.setattr(spill_mod, "BLOCK_ROWS", 7)
    monkeypatch.setattr(targets_mod, "BLOCK_FRAMES", 5)
    spilled = build_targets(motion, joints, humanoid, floor=contacts.floor)
    assert is_spilled(spilled.positions) and spilled.positions.flags.c_contiguous
    for name in ("positions", "orientations", "valid", "source_positions"):
        assert np.array_equal(getattr(spilled, name), getattr(held, name)), name
    assert _same(spilled.valid, held.valid)


def test_actor_rotations_and_toe_tips_kept_column_by_column_are_exact(walk, monkeypatch):
    """The actor's world rotations and extra joints (a rigid foot's toe tips) kept in temporary
    files laid out column by column (a column mapped in while read): the same values as in memory."""
    import physmocap.spill as spill_mod
    from physmocap.spill import is_spilled

    motion, joints, _ = walk
    idx, turning, extra = np.array([joints["pelvis"], joints["left_knee"]]), [joints["pelvis"], joints["left_wrist"]], [3]
    held = targets_mod._ActorKinematics(motion, idx, turning, None, None, extra=extra)
    monkeypatch.setattr(spill_mod, "SPILL_BYTES", 1)
    monkeypatch.setattr(targets_mod, "BLOCK_FRAMES", 5)
    spilled = targets_mod._ActorKinematics(motion, idx, turning, None, None, extra=extra)
    for name in ("rotations", "extra"):
        mine, theirs = getattr(spilled, name), getattr(held, name)
        assert mine.keys() == theirs.keys()
        for j, column in mine.items():
            assert is_spilled(column) and _same(column, theirs[j]) and column.shape == (motion.num_frames, column.shape[1])
    spilled.release()


def test_robot_targets_built_in_temporary_files_are_exact(walk, monkeypatch):
    """The robot (rigid feet: the toe tips read, the toe-line correction) with every array of
    build_targets spilled and tiny blocks: the same targets as in memory."""
    import physmocap.spill as spill_mod

    motion, joints, contacts = walk
    robot = load_character("robot")
    held = build_targets(motion, joints, robot, floor=contacts.floor)
    assert held.calibration.foot_tips, "the robot's feet are rigid"
    monkeypatch.setattr(spill_mod, "SPILL_BYTES", 1)
    monkeypatch.setattr(spill_mod, "BLOCK_ROWS", 7)
    monkeypatch.setattr(targets_mod, "BLOCK_FRAMES", 5)
    spilled = build_targets(motion, joints, robot, floor=contacts.floor)
    for name in ("positions", "orientations", "valid", "has_orientation"):
        assert np.array_equal(getattr(spilled, name), getattr(held, name)), name


def test_targets_from_given_kinematics_match_the_motions(walk, humanoid):
    motion, joints, contacts = walk
    own = build_targets(motion, joints, humanoid, floor=contacts.floor)
    given = build_targets(motion, joints, humanoid, floor=contacts.floor, kinematics=motion.forward_kinematics())
    assert np.array_equal(given.positions, own.positions) and np.array_equal(given.orientations, own.orientations)


def test_feet_levelled_on_their_own_columns_match_levelling_every_column(walk, humanoid):
    motion, joints, contacts = walk
    targets = build_targets(motion, joints, humanoid, floor=contacts.floor)
    raw_pos, raw_ori = targets.positions.copy(), targets.orientations.copy()
    pos, ori, levels = level_feet(targets.positions, targets.orientations, targets.has_orientation, targets.names,
                                  contacts.labels, character_rest_frames(humanoid), targets.fps)
    assert levels, "the walk's feet are levelled somewhere"
    copy = level_targets(targets, humanoid, contacts.labels)
    assert np.array_equal(copy.positions, pos) and _same(copy.orientations, ori) and copy.info["foot_levels"] == levels
    assert copy.positions[:, 3].flags.c_contiguous  # laid out joint by joint: planned a column at a time
    assert np.array_equal(targets.positions, raw_pos) and np.array_equal(targets.orientations, raw_ori)
    owned = level_targets(dataclasses.replace(targets, orientations=raw_ori), humanoid, contacts.labels, own_orientations=True)
    assert owned.orientations is raw_ori and np.array_equal(raw_ori, ori)
    assert np.array_equal(targets.positions, raw_pos)  # the positions are never levelled in place


def test_feet_levelled_in_place_match_a_copy(walk, humanoid):
    """level_feet(in_place=True) reads every value before it changes it: the same numbers
    as levelling a copy, in the arrays it was given."""
    motion, joints, contacts = walk
    targets = build_targets(motion, joints, humanoid, floor=contacts.floor)
    args = (targets.has_orientation, targets.names, contacts.labels, character_rest_frames(humanoid), targets.fps)
    pos, ori, levels = level_feet(targets.positions, targets.orientations, *args)
    mine = targets.positions.copy(), targets.orientations.copy()
    got = level_feet(*mine, *args, in_place=True)
    assert got[0] is mine[0] and got[1] is mine[1] and got[2] == levels
    assert np.array_equal(got[0], pos) and np.array_equal(got[1], ori) and not np.array_equal(pos, targets.positions)


def test_retarget_leaves_given_targets_alone(walk, humanoid):
    motion, joints, contacts = walk
    targets = build_targets(motion, joints, humanoid, floor=contacts.floor)
    before = targets.orientations.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        retarget(motion, humanoid, progress=False, start=0, targets=targets, max_iterations=1, contacts=contacts)
    assert np.array_equal(targets.orientations, before)


def _fidelity_fields_equal(a, b) -> bool:
    if dataclasses.is_dataclass(a):
        return all(_fidelity_fields_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_fidelity_fields_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    return a == b or (a != a and b != b)


def test_fidelity_from_blocks_and_the_joints_it_reads_is_exact(traj, monkeypatch):
    motion, ch = traj.source_motion, traj.character
    world = motion.world_positions()  # every joint, the whole clip: what the figures used to read
    actor = {n: np.array(world[:, j], dtype=float) for n, j in traj.joint_indices.items()}
    everything = fidelity_mod.fidelity(
        actor, fidelity_mod.character_joint_positions(traj), traj.fps, traj.targets.scale,
        model=ch.model, qpos=traj.qpos, velocity_limits=ch.velocity_limits,
        feet=foot_bodies(ch.model, ch.contacts),
    )
    drift = fidelity_mod.pelvis_drift(traj, fidelity_mod.character_joint_positions(traj)["pelvis"])
    everything = dataclasses.replace(everything, drift_mean_cm=drift[0], drift_max_cm=drift[1])  # the trajectory's own figure
    monkeypatch.setattr(fidelity_mod, "BLOCK_FRAMES", 7)
    assert _fidelity_fields_equal(fidelity_mod.trajectory_fidelity(traj), everything)
    picked = fidelity_mod.actor_joint_positions(motion, traj.joint_indices, {"left_knee"})
    assert list(picked) == ["left_knee"] and np.array_equal(picked["left_knee"], actor["left_knee"])


def test_fidelity_from_spilled_joint_columns_is_exact(traj, monkeypatch):
    """Every joint's positions in a temporary file, laid out joint by joint and let go
    segment by segment: the same figures as held in memory."""
    import physmocap.spill as spill_mod
    from physmocap.spill import is_spilled

    held = fidelity_mod.trajectory_fidelity(traj)
    monkeypatch.setattr(spill_mod, "SPILL_BYTES", 1)
    columns = fidelity_mod.actor_joint_positions(traj.source_motion, traj.joint_indices, fidelity_mod.figure_joints())
    assert all(is_spilled(c) and c.flags.c_contiguous for c in columns.values())
    assert _fidelity_fields_equal(fidelity_mod.trajectory_fidelity(traj), held)


def test_saturation_in_blocks_is_exact(traj, monkeypatch):
    ch = traj.character
    whole = fidelity_mod.saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups)
    monkeypatch.setattr(fidelity_mod, "BLOCK_FRAMES", 5)
    assert np.array_equal(fidelity_mod.saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups), whole)


@pytest.mark.parametrize(("up", "units"), [("Y", "m"), ("Z", "cm")])
def test_character_bvh_written_while_computed_has_write_bvhs_bytes(traj, tmp_path, monkeypatch, up, units):
    bvh_mod.write_bvh(character_motion(traj, up=up), tmp_path / "whole.bvh", units=units, up=up)
    monkeypatch.setattr(bvh_mod, "_ROWS_PER_BLOCK", 7)
    write_character_bvh(traj, tmp_path / "rows.bvh", up=up, units=units)
    assert (tmp_path / "rows.bvh").read_bytes() == (tmp_path / "whole.bvh").read_bytes()


def test_character_bvh_refuses_a_non_finite_frame_and_writes_nothing(humanoid, tmp_path, monkeypatch):
    qpos = np.tile(humanoid.model.qpos0, (20, 1))
    qpos[13, 10] = np.nan
    monkeypatch.setattr(bvh_mod, "_ROWS_PER_BLOCK", 4)
    with pytest.raises(OutputError) as err:
        write_character_bvh(Trajectory(character=humanoid, qpos=qpos, fps=30.0), tmp_path / "x.bvh")
    assert err.value.frame == 13 and "not finite" in str(err.value)
    assert not any(tmp_path.iterdir())


def test_bvh_rows_need_a_complete_layout(traj, tmp_path):
    motion = character_motion(traj)
    channels = dict(motion.meta["bvh_channels"])
    root = motion.skeleton.names[0]
    channels[root] = channels[root][:-1]  # two rotation axes: the third would have to be looked for first
    with pytest.raises(OptionError, match="three rotation"):
        bvh_mod.write_bvh_rows(tmp_path / "x.bvh", motion.skeleton, np.array([0]), channels, motion.num_frames,
                               motion.fps, lambda s, e: (motion.rotations[s:e], motion.translations[s:e]))


def test_retarget_lets_the_source_positions_go_and_gives_them_back_the_same(walk, humanoid, traj):
    motion, joints, contacts = walk
    assert traj.targets.__dict__["_source_positions"] is None  # not held after retargeting
    built = build_targets(traj.source_motion, traj.joint_indices, humanoid, floor=contacts.floor)
    assert _same(traj.targets.source_positions, built.source_positions)
    by_hand = dataclasses.replace(built, source_recipe=None)
    assert not by_hand.release_source_positions() and by_hand.source_positions is not None


def test_large_frees_are_returned_where_the_c_library_can(monkeypatch):
    import ctypes

    from physmocap.cli.retarget import return_large_frees_to_the_system

    try:
        glibc = hasattr(ctypes.CDLL(None), "mallopt")
    except (OSError, TypeError):
        glibc = False
    assert return_large_frees_to_the_system() is glibc

    def no_libc(*args, **kwargs):
        raise OSError("no C library")

    monkeypatch.setattr(ctypes, "CDLL", no_libc)
    assert return_large_frees_to_the_system() is False


def test_calibration_reads_the_motion_only_when_the_rest_pose_does_not_stand():
    """calibration_pose takes the clip's positions as a function, called only when the rest
    pose does not stand (build_targets then gathers only POSE_JOINTS' columns)."""
    from physmocap.ik.calibration import POSE_JOINTS, calibration_pose

    standing = {"left_hip": np.array([0.1, 0.0, 0.9]), "right_hip": np.array([-0.1, 0.0, 0.9]),
                "left_knee": np.array([0.1, 0.0, 0.5]), "right_knee": np.array([-0.1, 0.0, 0.5]),
                "left_ankle": np.array([0.1, 0.0, 0.1]), "right_ankle": np.array([-0.1, 0.0, 0.1]),
                "neck": np.array([0.0, 0.0, 1.5])}
    assert set(standing) <= POSE_JOINTS

    def never():
        raise AssertionError("the motion was read although the rest pose stands")

    assert calibration_pose(standing, never).frame is None
    sitting = dict(standing, neck=np.array([0.0, 0.6, 0.95]))  # the torso lies forward
    frames = {k: np.repeat(v[None], 3, axis=0) for k, v in standing.items()}
    pose = calibration_pose(sitting, lambda: frames)
    assert pose.frame == 0 and pose.standing
