"""Characters: the default humanoid, the robot and an unseen fixture biped, loaded and described."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from physmocap.canonical import REQUIRED_JOINTS
from physmocap.models import load_character
from physmocap.models.anthropometry import LENGTH_FRACTIONS, SEGMENT_MASS
from physmocap.models.geometry import character_geoms, geom_z_extent

FIXTURES = Path(__file__).parent / "fixtures"
CHARACTERS = [None, "robot", str(FIXTURES / "biped.xml")]
IDS = ["humanoid", "robot", "fixture_biped"]


@pytest.fixture(scope="module", params=CHARACTERS, ids=IDS)
def character(request):
    return load_character(request.param)


def _rest_data(ch):
    data = mujoco.MjData(ch.model)
    data.qpos[:] = ch.rest_qpos
    mujoco.mj_forward(ch.model, data)
    return data


def test_rest_pose_stands_on_the_floor(character):
    """mj_forward in the rest pose: no geom below z = 0, the lowest one touching it."""
    data = _rest_data(character)
    assert np.all(np.isfinite(data.xpos))
    lows = [geom_z_extent(character.model, data, g)[0] for g in character_geoms(character.model)]
    assert min(lows) > -1e-6
    assert min(lows) < 1e-6
    assert np.all(data.xpos[1:, 2] > 0.0)  # body origins above the floor


def test_contact_sites_on_the_floor(character):
    data = _rest_data(character)
    assert set(character.contacts) == {"left", "right"}
    for side, sites in character.contacts.items():
        assert len(sites) >= 2
        for s in sites:
            assert data.site(s).xpos[2] == pytest.approx(0.0, abs=1e-6), s
            assert (data.site(s).xpos[1] > 0) == (side == "left"), s


def test_description_is_complete(character):
    for j in REQUIRED_JOINTS:
        assert j in character.tracked, j
    rest = character.rest_positions()
    assert set(rest) == set(character.tracked)
    # Z-up, facing +X, left is +Y, pelvis above the origin.
    assert rest["pelvis"][:2] == pytest.approx([0.0, 0.0], abs=1e-9)
    assert rest["left_hip"][1] > 0 > rest["right_hip"][1]
    assert rest["left_shoulder"][1] > 0 > rest["right_shoulder"][1]
    assert rest["neck"][2] > rest["pelvis"][2] > rest["left_knee"][2] > rest["left_ankle"][2]
    if "left_toe" in rest:
        assert rest["left_toe"][0] > rest["left_ankle"][0]
    assert character.hip_height == pytest.approx(
        (rest["left_hip"][2] + rest["right_hip"][2]) / 2.0
    )
    assert 0.3 < character.hip_height / character.height < 0.7
    assert character.total_mass > 0
    for (parent, child), length in character.segment_lengths.items():
        assert parent in character.tracked and child in character.tracked
        assert length == pytest.approx(float(np.linalg.norm(rest[child] - rest[parent])))
        assert length > 0
    assert character.rest_qpos.shape == (character.model.nq,)
    assert not character.rest_qpos.flags.writeable


def test_limits_cover_every_hinge(character):
    model = character.model
    hinges = [model.joint(j).name for j in range(model.njnt)
              if int(model.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))]
    assert list(character.joint_limits) == hinges
    assert set(character.velocity_limits) == set(hinges)
    for name in hinges:
        lo, hi = character.joint_limits[name]
        assert math.isfinite(lo) and math.isfinite(hi) and lo < hi, name
        j = model.joint(name).id
        assert tuple(model.jnt_range[j]) == (lo, hi)
        q = character.rest_qpos[model.jnt_qposadr[j]]
        assert lo <= q <= hi, name
        assert character.velocity_limits[name] > 0


def test_robot_is_different():
    robot = load_character("robot")
    human = load_character()
    assert robot.height == pytest.approx(1.3, abs=1e-6)
    assert robot.model.nv < human.model.nv
    assert "left_clavicle" not in robot.tracked and "left_toe_end" not in robot.tracked
    names = {robot.model.joint(j).name for j in range(robot.model.njnt)}
    assert not names & {human.model.joint(j).name for j in range(human.model.njnt)}
    # Some body frames are rotated away from the world frame at rest, and some hinge axes
    # are not aligned with any world axis (tilted hip yaw).
    data = _rest_data(robot)
    rotated = [b for b in range(1, robot.model.nbody)
               if not np.allclose(data.xmat[b].reshape(3, 3), np.eye(3), atol=1e-6)]
    assert len(rotated) >= 4
    tilted = [j for j in range(robot.model.njnt)
              if int(robot.model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE)
              and np.max(np.abs(data.xaxis[j])) < 0.99]
    assert len(tilted) >= 2
    # Velocity limits from the mapping file (deg/s -> rad/s).
    assert robot.velocity_limits["l_knee"] == pytest.approx(math.radians(1150))
    assert robot.velocity_limits["waist_yaw"] == pytest.approx(math.radians(860))


def test_fixture_is_stood_up_from_y_up():
    ch = load_character(FIXTURES / "biped.xml")
    assert ch.name == "stilt_biped"
    assert ch.root_joint == "free"
    assert all(tf.kind == "body" for tf in ch.tracked.values())
    # qpos root quaternion takes the model's Y-up, Z-forward frame to Z-up, X-forward.
    assert ch.height == pytest.approx(1.59, abs=1e-6)
    # knees: no range in the MJCF, [joint_limits] in the mapping gives one, in degrees.
    assert ch.joint_limits["kneeL"] == pytest.approx((math.radians(-2), math.radians(150)))
    assert ch.velocity_limits["ankleL"] == pytest.approx(math.radians(720))


def test_default_humanoid_rest_is_zero_hinges():
    ch = load_character()
    assert ch.name == "humanoid" and ch.root_joint == "root"
    assert np.all(ch.rest_qpos[7:] == 0.0)
    assert np.allclose(ch.rest_qpos[3:7], [1, 0, 0, 0])
    data = _rest_data(ch)
    # every body frame is aligned with the world at rest
    for b in range(1, ch.model.nbody):
        assert np.allclose(data.xmat[b].reshape(3, 3), np.eye(3)), ch.model.body(b).name
    # every canonical joint has a site of that name on the body it moves
    for canon, tf in ch.tracked.items():
        assert tf.kind == "site" and tf.name == canon


def test_humanoid_segments_follow_winter():
    """Segment lengths and masses of the default humanoid agree with Winter (2009)."""
    ch = load_character()
    H = 1.75
    seg = ch.segment_lengths
    f = LENGTH_FRACTIONS
    for side in ("left", "right"):
        assert seg[(f"{side}_shoulder", f"{side}_elbow")] == pytest.approx(f["upper_arm"] * H, abs=1e-5)
        assert seg[(f"{side}_elbow", f"{side}_wrist")] == pytest.approx(f["forearm"] * H, abs=1e-5)
        assert seg[(f"{side}_wrist", f"{side}_hand_end")] == pytest.approx(f["hand"] * H, abs=1e-5)
        assert seg[(f"{side}_hip", f"{side}_knee")] == pytest.approx(f["thigh"] * H, abs=1e-5)
        assert seg[(f"{side}_knee", f"{side}_ankle")] == pytest.approx(f["shank"] * H, abs=1e-5)
    rest = ch.rest_positions()
    assert ch.hip_height == pytest.approx(f["hip"] * H, abs=1e-5)
    assert rest["left_knee"][2] == pytest.approx(f["knee"] * H, abs=1e-5)
    assert rest["left_ankle"][2] == pytest.approx(f["ankle"] * H, abs=1e-5)
    assert rest["left_shoulder"][2] == pytest.approx(f["shoulder"] * H, abs=1e-5)
    assert rest["head"][2] == pytest.approx(f["chin"] * H, abs=1e-5)
    assert rest["head_end"][2] == pytest.approx(H, abs=1e-5)
    assert rest["left_shoulder"][1] - rest["right_shoulder"][1] == pytest.approx(f["shoulder_width"] * H, abs=1e-5)
    assert rest["left_toe_end"][0] - ch.model.site("left_heel").pos[0] > 0.9 * f["foot_length"] * H
    # fingertips at Winter's 0.377 H
    assert rest["left_hand_end"][2] == pytest.approx(0.377 * H, abs=0.002)
    # masses: Winter's fractions
    m = ch.model
    M = ch.total_mass
    assert M == pytest.approx(70.0)
    assert m.body("left_thigh").mass[0] == pytest.approx(SEGMENT_MASS["thigh"].mass * M)
    assert m.body("left_upper_arm").mass[0] == pytest.approx(SEGMENT_MASS["upper_arm"].mass * M)
    assert m.body("left_shank").mass[0] == pytest.approx(SEGMENT_MASS["shank"].mass * M)
    # a thigh's transverse inertia from Winter's radius of gyration about the centre of mass
    k, L = SEGMENT_MASS["thigh"].gyration, f["thigh"] * H
    assert m.body("left_thigh").inertia[0] == pytest.approx(SEGMENT_MASS["thigh"].mass * M * (k * L) ** 2, rel=1e-4)


def test_scene_files_load():
    from physmocap.resources import mjcf_dir

    for scene, character in (("scene.xml", "humanoid"), ("scene_robot.xml", "robot")):
        ch = load_character(mjcf_dir() / scene)
        assert ch.name == character
        model = ch.model
        assert model.geom("floor").type == mujoco.mjtGeom.mjGEOM_PLANE
        data = _rest_data(ch)
        # contacts with the floor only, never between the character's own geoms
        for c in data.contact[: data.ncon]:
            assert 0 in (model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2])


def test_no_self_collision_pairs():
    """Every character geom collides with the floor (contype 1 / conaffinity 1) but not with itself."""
    for name in ("humanoid", "robot"):
        m = load_character(name).model
        geoms = character_geoms(m, collision_only=True)
        assert geoms
        for a in geoms:
            assert (m.geom_conaffinity[a] & 1) or (m.geom_contype[a] & 1)
            for b in geoms:
                assert not (m.geom_contype[a] & m.geom_conaffinity[b]), (m.geom(a).name, m.geom(b).name)


def test_range_policy_strict_and_overrides(tmp_path):
    default = load_character()
    strict = load_character(range_policy="strict")
    lo_d, hi_d = default.joint_limits["left_knee_flexion"]
    lo_s, hi_s = strict.joint_limits["left_knee_flexion"]
    assert hi_s < hi_d and lo_s >= lo_d
    assert strict.model.jnt_range[strict.model.joint("left_knee_flexion").id][1] == hi_s
    # a user mapping can widen one limit and change a speed
    text = (Path(default.map_path).read_text()
            + "\n[joint_limits]\nleft_knee_flexion = [-5, 175]\n"
            + "\n[velocity_limits]\nleft_knee_flexion = 3000\n")
    mp = tmp_path / "wide.map.toml"
    mp.write_text(text)
    wide = load_character(None, mp)
    assert wide.joint_limits["left_knee_flexion"] == pytest.approx((math.radians(-5), math.radians(175)))
    assert wide.velocity_limits["left_knee_flexion"] == pytest.approx(math.radians(3000))
    assert wide.joint_limits["right_knee_flexion"] == default.joint_limits["right_knee_flexion"]


def test_humanoid_centre_of_mass_is_human():
    """Whole-body centre of mass at 55-58 % of stature (standing adults), over the feet."""
    ch = load_character()
    data = _rest_data(ch)
    com = data.subtree_com[0]
    assert 0.54 < com[2] / ch.height < 0.59
    assert com[1] == pytest.approx(0.0, abs=1e-9)
    heel = data.site("left_heel").xpos[0]
    toe = data.site("left_toe_tip").xpos[0]
    assert heel < com[0] < toe
