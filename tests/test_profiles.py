"""Canonical name mapping: profiles, detection by names and by shape, rules, user maps."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import SHARED_BVH, shared_file
from physmocap.canonical import CANONICAL_NAMES, REQUIRED_JOINTS
from physmocap.errors import InputError, MappingError, OptionError, PhysmocapWarning
from physmocap.motion import Motion, Skeleton
from physmocap.rotations import up_axis_matrix
from physmocap.sources import load_motion
from physmocap.sources.profiles import (
    PROFILES,
    JointMap,
    canonical_confidence,
    canonical_positions,
    canonical_rest_positions,
    canonical_rotations,
    detect_profile,
    load_mapping_file,
    map_skeleton,
    normalize_name,
    skeleton_keys,
)
from physmocap.sources.profiles.rules import spine_chest
from physmocap.sources.profiles.structure import SkeletonView

FIXTURES = Path(__file__).parent / "fixtures" / "profiles"

# ---------------------------------------------------------------------------
# helpers


def build(spec, scale: float = 0.01, up: str = "Y") -> Skeleton:
    """A skeleton from a nested ``(name, offset, [children])`` spec (file axes, file units).

    A child named ``"End"`` is an end site called ``<parent>_End``.
    """
    R = up_axis_matrix(up, "Z")
    names, parents, offsets, ends = [], [], [], []

    def walk(node, parent):
        name, off, kids = node
        if name == "End":
            name = f"{names[parent]}_End"
        names.append(name)
        parents.append(parent)
        offsets.append(R @ np.asarray(off, dtype=float) * scale)
        ends.append(node[0] == "End")
        me = len(names) - 1
        for k in kids:
            walk(k, me)

    walk(spec, -1)
    return Skeleton(tuple(names), np.array(parents), np.array(offsets), np.array(ends))


def chain(items, tail=None):
    """``[(name, offset), ...]`` -> nested spec; ``tail`` an end-site offset or a list of subtrees."""
    name, off = items[0]
    if len(items) == 1:
        kids = tail if isinstance(tail, list) else ([("End", tail, [])] if tail is not None else [])
        return (name, off, kids)
    return (name, off, [chain(items[1:], tail)])


def mirror(spec, pairs=(("Left", "Right"), ("_L", "_R"), ("_l", "_r"))):
    name, off, kids = spec
    new = name
    for a, b in pairs:
        if a in name:
            new = name.replace(a, b)
            break
    else:
        if len(name) > 1 and name[0] == "l" and name[1].isupper():
            new = "r" + name[1:]
        elif name.startswith("L ") or name.startswith("Bip01 L "):
            new = name.replace("L ", "R ", 1)
    return (new, (-off[0], off[1], off[2]), [mirror(k, pairs) for k in kids])


def rest_motion(skel: Skeleton, frames: int = 3) -> Motion:
    J = skel.num_joints
    rot = np.zeros((frames, J, 4))
    rot[..., 3] = 1.0
    return Motion(skel, 30.0, rotations=rot, translations=np.zeros((frames, 1, 3)) + skel.offsets[0],
                  translated=np.array([0]))


def bone_local(skel: Skeleton, frames: int = 3) -> Motion:
    """The same body written with bone-local offsets (LAFAN1 / Bandai Namco style).

    Each joint's frame turns +X onto its first child's bone, so the rest pose
    (all local rotations identity) lays every bone along one axis; frame data
    restores the standing body.
    """
    J = skel.num_joints
    world_rot = []
    kids = [[c for c in range(J) if skel.parents[c] == j] for j in range(J)]
    for j in range(J):
        real = [c for c in kids[j] if np.linalg.norm(skel.offsets[c]) > 1e-9]
        if real:
            d = np.array(skel.offsets[real[0]]) / np.linalg.norm(skel.offsets[real[0]])
            r, _ = Rotation.align_vectors([d], [[1.0, 0.0, 0.0]])
        else:
            r = Rotation.identity()
        world_rot.append(r)
    offsets = np.array(skel.offsets, dtype=float)
    local = np.zeros((J, 4))
    for j in range(J):
        p = int(skel.parents[j])
        if p >= 0:
            offsets[j] = world_rot[p].inv().apply(np.array(skel.offsets[j]))
            local[j] = (world_rot[p].inv() * world_rot[j]).as_quat()
        else:
            local[j] = world_rot[j].as_quat()
    local_skel = Skeleton(skel.names, skel.parents, offsets, skel.end_site)
    rot = np.broadcast_to(local, (frames, J, 4)).copy()
    roots = np.array(skel.roots())
    trans = np.broadcast_to(skel.offsets[roots], (frames, len(roots), 3)).copy()
    return Motion(local_skel, 30.0, rotations=rot, translations=trans, translated=roots)


def facing_lateral(pos: np.ndarray, jm: JointMap, names) -> float:
    """Signed distance of the left hip from the right hip along the body's left axis
    (``up x forward``, forward from the feet) in pose ``pos``."""
    idx = jm.indices
    fwd = []
    for side in ("left", "right"):
        tip = idx.get(f"{side}_toe", idx.get(f"{side}_toe_end"))
        fwd.append(pos[tip, :2] - pos[idx[f"{side}_ankle"], :2])
    f = np.mean(fwd, axis=0)
    left_axis = np.array([-f[1], f[0]]) / np.linalg.norm(f)
    return float((pos[idx["left_hip"], :2] - pos[idx["right_hip"], :2]) @ left_axis)


def assert_sides(jm: JointMap, skel: Skeleton, pos: np.ndarray | None = None) -> None:
    """Left canonical joints come from the source's left joints, by name and by geometry."""
    for c, j in jm.indices.items():
        if skel.end_site[j]:  # end sites are named after their parent joint
            j = int(skel.parents[j])
        n = normalize_name(skel.names[j])
        if c.startswith("left_"):
            assert re.search(r"left|^l(?!eg)|_l$|l$", n) and "right" not in n, (c, skel.names[j])
        if c.startswith("right_"):
            assert re.search(r"right|^r|_r$|r$", n) and "left" not in n, (c, skel.names[j])
    if pos is not None:
        assert facing_lateral(pos, jm, skel.names) > 0.05


def names_of(jm: JointMap) -> dict[str, str]:
    return {c: jm.describe(c) for c in jm.mapped}


# ---------------------------------------------------------------------------
# names


@pytest.mark.parametrize(
    "raw, key",
    [
        ("mixamorig:LeftUpLeg", "leftupleg"),
        ("mixamorig_LeftUpLeg", "leftupleg"),
        ("mixamorig1:Hips", "hips"),
        ("Character1_LeftForeArm", "leftforearm"),
        ("Bip01 L Thigh", "lthigh"),
        ("Bip01", "bip01"),
        ("XN_SKEL_LEFT_HIP", "lefthip"),
        ("nite::JOINT_LEFT_KNEE", "leftknee"),
        ("K4ABT_JOINT_SPINE_NAVEL", "spinenavel"),
        ("JointType_SpineBase", "spinebase"),
        ("joint_Root", "root"),
        ("Skeleton001_LThigh", "lthigh"),
        ("Take 001|Hips", "hips"),
        ("left-hip", "lefthip"),
        ("Left Hip", "lefthip"),
        ("upperarm.L", "upperarml"),
        ("Shoulder_L", "shoulderl"),
    ],
)
def test_normalize_name(raw, key):
    assert normalize_name(raw) == key


def test_skeleton_keys_strip_a_shared_prefix_and_report_tool_prefixes():
    keys, prefix = skeleton_keys(["Model_Hips", "Model_Spine", "Model_LeftUpLeg", "Model_RightUpLeg"])
    assert keys == ["hips", "spine", "leftupleg", "rightupleg"]
    keys, prefix = skeleton_keys(["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Neck", "mixamorig:Head"])
    assert keys == ["hips", "spine", "neck", "head"] and prefix == "mixamorig"
    # a shared side token is not a prefix
    keys, _ = skeleton_keys(["L_hip", "L_knee", "L_ankle", "L_toe"])
    assert keys == ["lhip", "lknee", "lankle", "ltoe"]


def test_profile_tables_are_consistent():
    for p in PROFILES.values():
        assert set(p.joints) <= set(CANONICAL_NAMES), p.name
        missing = [c for c in REQUIRED_JOINTS if c not in p.joints]
        # only OpenNI has no pelvis joint (it is derived from the hips)
        assert missing == ([] if p.name != "openni" else ["pelvis"]), (p.name, missing)
        for c, cands in p.joints.items():
            assert cands and all(isinstance(n, str) and n for n in cands), (p.name, c)


# ---------------------------------------------------------------------------
# the real recordings

CMU_EXPECTED = {
    "pelvis": "Hips", "spine": "Spine", "chest": "Spine1", "neck": "Neck1", "head": "Head",
    "head_end": "Head_End",
    "left_clavicle": "LeftShoulder", "left_shoulder": "LeftArm", "left_elbow": "LeftForeArm",
    "left_wrist": "LeftHand", "left_hip": "LeftUpLeg", "left_knee": "LeftLeg",
    "left_ankle": "LeftFoot", "left_toe": "LeftToeBase", "left_toe_end": "LeftToeBase_End",
    "right_clavicle": "RightShoulder", "right_shoulder": "RightArm", "right_elbow": "RightForeArm",
    "right_wrist": "RightHand", "right_hip": "RightUpLeg", "right_knee": "RightLeg",
    "right_ankle": "RightFoot", "right_toe": "RightToeBase", "right_toe_end": "RightToeBase_End",
}
EXPECTED = {
    "cmu_12_01_walk.bvh": ("cmu", {**CMU_EXPECTED, "left_hand_end": "LeftHandIndex1",
                                   "right_hand_end": "RightHandIndex1"}),
    "cmu_01_01_jumps.bvh": ("cmu", {**CMU_EXPECTED, "left_hand_end": "LFingers",
                                    "right_hand_end": "RFingers"}),
    "optitrack_hops_crouch.bvh": ("optitrack", {
        **CMU_EXPECTED, "neck": "Neck", "left_hand_end": "LeftHand_End",
        "right_hand_end": "RightHand_End"}),
    "pymo_walk.bvh": ("pymo", {
        **{k: v for k, v in CMU_EXPECTED.items() if k not in ("chest", "head", "neck")},
        "neck": "Head", "left_hand_end": "LeftHand_End", "right_hand_end": "RightHand_End"}),
}


@pytest.mark.parametrize("name", SHARED_BVH)
def test_shared_recordings_map_every_joint_correctly(name):
    motion = load_motion(shared_file(name))
    profile, expected = EXPECTED[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        jm = map_skeleton(motion)
    assert jm.profile == profile
    assert names_of(jm) == expected
    assert jm.missing() == ()
    # left/right by the source's names and by geometry, at the rest pose and in motion
    skel = motion.skeleton
    assert_sides(jm, skel, skel.rest_positions())
    world = motion.world_positions()
    for f in np.linspace(0, motion.num_frames - 1, 7).astype(int):
        assert facing_lateral(world[f], jm, skel.names) > 0.05


@pytest.mark.parametrize("name", SHARED_BVH)
def test_topology_on_scrambled_names_matches_the_name_mapping(name):
    motion = load_motion(shared_file(name))
    by_name = map_skeleton(motion)
    rng = np.random.default_rng(7)
    skel = motion.skeleton
    scrambled = [f"j{k}" for k in rng.permutation(skel.num_joints)]
    anon = Skeleton(tuple(scrambled), skel.parents, skel.offsets, skel.end_site)
    jm = map_skeleton(anon)
    assert jm.profile == "topology"
    expected = dict(by_name.indices)
    if name.startswith("cmu"):
        # CMU's LeftShoulder sits on Spine1 (zero-length bone): no clavicle by shape
        expected.pop("left_clavicle")
        expected.pop("right_clavicle")
    assert dict(jm.indices) == expected
    assert jm.missing() == ()


def test_topology_ignores_child_order():
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    skel = motion.skeleton
    # rebuild with every joint's children in reverse order (parents still first)
    order: list[int] = []

    def walk(j):
        order.append(j)
        for c in reversed([c for c in range(skel.num_joints) if skel.parents[c] == j]):
            walk(c)

    walk(0)
    new_of = {old: new for new, old in enumerate(order)}
    parents = np.array([-1 if skel.parents[o] < 0 else new_of[int(skel.parents[o])] for o in order])
    anon = Skeleton(tuple(f"x{k}" for k in range(len(order))), parents, skel.offsets[order],
                    skel.end_site[order])
    jm = map_skeleton(anon)
    ref = map_skeleton(motion)
    back = {c: order[j] for c, j in jm.indices.items()}
    for c, j in back.items():
        assert ref.indices[c] == j, c


# ---------------------------------------------------------------------------
# vendor fixtures (BVH files written for these tests)


def _mb(prefix=""):
    """MotionBuilder-style expectations for the limbs."""
    out = {}
    for side in ("Left", "Right"):
        s = side.lower()
        out.update({
            f"{s}_clavicle": f"{prefix}{side}Shoulder", f"{s}_shoulder": f"{prefix}{side}Arm",
            f"{s}_elbow": f"{prefix}{side}ForeArm", f"{s}_wrist": f"{prefix}{side}Hand",
            f"{s}_hip": f"{prefix}{side}UpLeg", f"{s}_knee": f"{prefix}{side}Leg",
            f"{s}_ankle": f"{prefix}{side}Foot",
        })
    return out


FIXTURE_EXPECTED = {
    "mixamo_ybot.bvh": ("mixamo", {
        **_mb("mixamorig:"), "pelvis": "mixamorig:Hips", "spine": "mixamorig:Spine",
        "chest": "mixamorig:Spine1", "neck": "mixamorig:Neck", "head": "mixamorig:Head",
        "head_end": "mixamorig:HeadTop_End",
        "left_hand_end": "mixamorig:LeftHandMiddle1", "right_hand_end": "mixamorig:RightHandMiddle1",
        "left_toe": "mixamorig:LeftToeBase", "right_toe": "mixamorig:RightToeBase",
        "left_toe_end": "mixamorig:LeftToe_End", "right_toe_end": "mixamorig:RightToe_End"}),
    "daz_poser.bvh": ("daz", {
        "pelvis": "hip", "spine": "abdomen", "chest": "chest", "neck": "neck", "head": "head",
        "left_clavicle": "lCollar", "left_shoulder": "lShldr", "left_elbow": "lForeArm",
        "left_wrist": "lHand", "left_hand_end": "lMid1", "left_hip": "lThigh", "left_knee": "lShin",
        "left_ankle": "lFoot", "left_toe_end": "lFoot_End",
        "right_clavicle": "rCollar", "right_shoulder": "rShldr", "right_elbow": "rForeArm",
        "right_wrist": "rHand", "right_hand_end": "rMid1", "right_hip": "rThigh", "right_knee": "rShin",
        "right_ankle": "rFoot", "right_toe_end": "rFoot_End"}),
    "xsens_mvn.bvh": ("xsens", {
        "pelvis": "Hips", "spine": "Chest2", "chest": "Chest3", "neck": "Neck", "head": "Head",
        "head_end": "Head_End",
        **{f"{s.lower()}_{c}": f"{s}{n}" for s in ("Left", "Right") for c, n in (
            ("clavicle", "Collar"), ("shoulder", "Shoulder"), ("elbow", "Elbow"), ("wrist", "Wrist"),
            ("hand_end", "Wrist_End"), ("hip", "Hip"), ("knee", "Knee"), ("ankle", "Ankle"),
            ("toe", "Toe"), ("toe_end", "Toe_End"))}}),
    "perception_neuron.bvh": ("perception_neuron", {
        **_mb(), "pelvis": "Hips", "spine": "Spine1", "chest": "Spine2", "neck": "Neck",
        "head": "Head", "head_end": "Head_End",
        "left_hand_end": "LeftHandMiddle1", "right_hand_end": "RightHandMiddle1",
        "left_toe_end": "LeftFoot_End", "right_toe_end": "RightFoot_End"}),
}


@pytest.mark.parametrize("name", sorted(FIXTURE_EXPECTED))
def test_vendor_fixture_files(name):
    motion = load_motion(FIXTURES / name)
    profile, expected = FIXTURE_EXPECTED[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        jm = map_skeleton(motion)
    assert jm.profile == profile
    assert names_of(jm) == expected
    assert_sides(jm, motion.skeleton, motion.skeleton.rest_positions())
    # the shape alone finds the same limbs
    topo = map_skeleton(motion, profile="topology")
    for c in ("pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
              "right_ankle", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
              "left_wrist", "right_wrist", "neck"):
        assert topo.indices[c] == jm.indices[c], c


# ---------------------------------------------------------------------------
# vendor skeletons built here


def _spine(names, lengths, top):
    return chain([(n, (0, L, 0)) for n, L in zip(names, lengths)], top)


def lafan1_skeleton() -> Skeleton:
    arm = chain([("LeftShoulder", (4, 8, 0)), ("LeftArm", (13, 0, 0)), ("LeftForeArm", (27, 0, 0)),
                 ("LeftHand", (25, 0, 0))])
    leg = chain([("LeftUpLeg", (10, -4, 0)), ("LeftLeg", (0, -43, 0)), ("LeftFoot", (0, -42, 0)),
                 ("LeftToe", (0, -7, 13))])
    top = ("Spine2", (0, 12, 0), [chain([("Neck", (0, 15, 0)), ("Head", (0, 10, 2))]), arm, mirror(arm)])
    spine = _spine(["Spine", "Spine1"], [10, 11], [top])
    return build(("Hips", (0, 95, 0), [leg, mirror(leg), spine]))


def bandai_skeleton() -> Skeleton:
    arm = chain([("Shoulder_L", (5, 13, 0)), ("UpperArm_L", (5, 0, 0)), ("LowerArm_L", (24, 0, 0)),
                 ("Hand_L", (22, 0, 0))], (0, 0, 0))
    leg = chain([("UpperLeg_L", (6.5, -2, 0)), ("LowerLeg_L", (0, -39, 0)), ("Foot_L", (0, -41, 0)),
                 ("Toes_L", (0, -7, 10))], (0, 0, 0))
    chest = ("Chest", (0, 9, 0), [chain([("Neck", (0, 16.4, 0)), ("Head", (0, 6.5, 0))], (0, 0, 0)),
                                  arm, mirror(arm)])
    hips = ("Hips", (0, 94, 0), [("Spine", (0, 15.7, 0), [chest]), leg, mirror(leg)])
    return build(("joint_Root", (0, 0, 0), [hips]))


@pytest.mark.parametrize(
    "make, profile, expected",
    [
        (lafan1_skeleton, "lafan1", {
            **{k: v for k, v in _mb().items()}, "pelvis": "Hips", "spine": "Spine", "chest": "Spine1",
            "neck": "Neck", "head": "Head", "left_toe": "LeftToe", "right_toe": "RightToe"}),
        (bandai_skeleton, "bandai_namco", {
            "pelvis": "Hips", "spine": "Spine", "chest": "Chest", "neck": "Neck", "head": "Head",
            **{f"{s}_{c}": f"{n}_{s[0].upper()}" for s in ("left", "right") for c, n in (
                ("clavicle", "Shoulder"), ("shoulder", "UpperArm"), ("elbow", "LowerArm"),
                ("wrist", "Hand"), ("hip", "UpperLeg"), ("knee", "LowerLeg"), ("ankle", "Foot"),
                ("toe", "Toes"))}}),
    ],
)
def test_bone_local_rest_poses_use_an_animated_frame(make, profile, expected):
    """LAFAN1 and Bandai Namco store bone-local offsets: the rest pose is no body."""
    motion = bone_local(make())
    assert not _upright(motion.skeleton.rest_positions())
    jm = map_skeleton(motion)
    assert jm.profile == profile and jm.pose.startswith("frame")
    # zero-length end sites (Bandai) are not segment tips
    assert names_of(jm) == expected
    world = motion.world_positions()
    assert_sides(jm, motion.skeleton, world[0])
    # the names work from the skeleton alone too, without a false left/right alarm
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        alone = map_skeleton(motion.skeleton)
    assert {c: jm.indices[c] for c in REQUIRED_JOINTS} == {c: alone.indices[c] for c in REQUIRED_JOINTS}
    assert alone.pose == "rest pose"
    # but the shape cannot be read from that rest pose
    with pytest.raises(MappingError, match="tried the skeleton's shape"):
        map_skeleton(motion.skeleton, profile="topology")
    # and the shape, read from the frame, agrees on the limbs
    topo = map_skeleton(Motion(
        Skeleton(tuple(f"n{k}" for k in range(motion.skeleton.num_joints)), motion.skeleton.parents,
                 motion.skeleton.offsets, motion.skeleton.end_site),
        30.0, rotations=motion.rotations, translations=motion.translations,
        translated=motion.translated))
    for c in ("left_hip", "right_knee", "left_ankle", "right_elbow", "left_wrist", "neck"):
        assert topo.indices[c] == jm.indices[c], c


def _upright(p):
    ext = np.ptp(p, axis=0)
    return ext[2] >= 0.6 * max(ext[0], ext[1])


def test_prefixed_and_biped_and_mocapbank_skeletons():
    # MotionBuilder HumanIK with the Character1_ prefix and roll bones
    arm = chain([("Character1_LeftShoulder", (6, 9, 0)), ("Character1_LeftArm", (13, 0, 0)),
                 ("Character1_LeftArmRoll", (13, 0, 0)), ("Character1_LeftForeArm", (14, 0, 0)),
                 ("Character1_LeftHand", (26, 0, 0))], (8, 0, 0))
    leg = chain([("Character1_LeftUpLeg", (9, -6, 0)), ("Character1_LeftLeg", (0, -42, 0)),
                 ("Character1_LeftFoot", (0, -42, 0)), ("Character1_LeftToeBase", (0, -7, 12))], (0, 0, 8))
    top = ("Character1_Spine2", (0, 13, 0), [
        chain([("Character1_Neck", (0, 15, 0)), ("Character1_Head", (0, 10, 0))], (0, 18, 0)),
        arm, mirror(arm)])
    hik = build(("Character1_Hips", (0, 100, 0), [
        _spine(["Character1_Spine", "Character1_Spine1"], [10, 12], [top]), leg, mirror(leg)]))
    jm = map_skeleton(hik)
    assert jm.profile == "motionbuilder"
    assert jm.source_name(hik, "left_shoulder") == "Character1_LeftArm"
    assert jm.source_name(hik, "left_elbow") == "Character1_LeftForeArm"  # not the roll bone
    assert jm.source_name(hik, "right_toe") == "Character1_RightToeBase"
    assert_sides(jm, hik, hik.rest_positions())

    # 3ds Max Biped
    barm = chain([("Bip01 L Clavicle", (3, 14, 0)), ("Bip01 L UpperArm", (14, 0, 0)),
                  ("Bip01 L Forearm", (28, 0, 0)), ("Bip01 L Hand", (25, 0, 0)),
                  ("Bip01 L Finger2", (9, 0, 0))], (8, 0, 0))
    bleg = chain([("Bip01 L Thigh", (9, -3, 0)), ("Bip01 L Calf", (0, -43, 0)),
                  ("Bip01 L Foot", (0, -43, 0)), ("Bip01 L Toe0", (0, -7, 13)),
                  ("Bip01 L Toe0Nub", (0, 0, 6))])
    bneck = chain([("Bip01 Neck", (0, 14, 0)), ("Bip01 Head", (0, 8, 0)), ("Bip01 HeadNub", (0, 18, 0))])
    bsp = chain([("Bip01 Spine", (0, 10, 0)), ("Bip01 Spine1", (0, 14, 0)), ("Bip01 Spine2", (0, 14, 0))],
                [bneck, barm, mirror(barm)])
    biped = build(("Bip01", (0, 96, 0), [("Bip01 Pelvis", (0, 0, 0), [bsp, bleg, mirror(bleg)])]))
    jm = map_skeleton(biped)
    assert jm.profile == "biped"
    assert names_of(jm)["pelvis"] == "Bip01 Pelvis"
    assert names_of(jm)["right_knee"] == "Bip01 R Calf"
    assert names_of(jm)["left_shoulder"] == "Bip01 L UpperArm"
    assert names_of(jm)["head_end"] == "Bip01 HeadNub"
    assert names_of(jm)["left_toe_end"] == "Bip01 L Toe0Nub"
    assert_sides(jm, biped, biped.rest_positions())

    # MocapBank: Xsens-style names, Chest/Chest2, collars at the neck, arms down, no toes
    marm = chain([("LeftCollar", (0, 16.9, 0.3)), ("LeftShoulder", (16.0, -3.1, 2.1)),
                  ("LeftElbow", (2.6, -25.4, 1.7)), ("LeftWrist", (2.4, -22.5, 1.0))], (1.5, -14.0, 1.2))
    mleg = chain([("LeftHip", (9.3, 0, 3.5)), ("LeftKnee", (-0.5, -48.8, 0.3)),
                  ("LeftAnkle", (0.2, -38.5, -4.3))], (1.2, -7.4, 17.8))
    mc2 = ("Chest2", (0.3, 15.8, -2.6), [
        marm, mirror(marm), chain([("Neck", (0, 16.9, 0.3)), ("Head", (0.1, 11.4, 4.7))], (0, 18.0, 0.3))])
    mb = build(("Hips", (0, 93, 0), [("Chest", (-0.2, 10.3, 0.1), [mc2]), mleg, mirror(mleg)]))
    jm = map_skeleton(mb)
    assert jm.profile == "mocapbank"
    assert names_of(jm) == {
        "pelvis": "Hips", "spine": "Chest", "chest": "Chest2", "neck": "Neck", "head": "Head",
        "head_end": "Head_End",
        **{f"{s.lower()}_{c}": f"{s}{n}" for s in ("Left", "Right") for c, n in (
            ("clavicle", "Collar"), ("shoulder", "Shoulder"), ("elbow", "Elbow"), ("wrist", "Wrist"),
            ("hand_end", "Wrist_End"), ("hip", "Hip"), ("knee", "Knee"), ("ankle", "Ankle"),
            ("toe_end", "Ankle_End"))},
    }
    assert_sides(jm, mb, mb.rest_positions())


# ---------------------------------------------------------------------------
# trackers (positional)

# a standing body, metres, in body axes (x = left, y = forward, z = up), arms down
BODY = {
    "pelvis": (0, 0, 0.95), "l_hip": (0.09, 0, 0.93), "l_knee": (0.09, 0.01, 0.50),
    "l_ankle": (0.09, -0.02, 0.08), "l_ball": (0.09, 0.12, 0.02), "l_tip": (0.09, 0.18, 0.0),
    "navel": (0, 0, 1.10), "t12": (0, -0.02, 1.24), "chest": (0, 0.0, 1.32),
    "neck_base": (0, -0.02, 1.45), "mid_neck": (0, 0, 1.52), "c1": (0, 0, 1.58),
    "head_c": (0, 0.02, 1.65), "head_top": (0, 0, 1.76), "nose": (0, 0.1, 1.63),
    "l_eye": (0.03, 0.08, 1.67), "l_ear": (0.07, 0.0, 1.65),
    "l_sc": (0.02, 0.03, 1.42), "l_shoulder": (0.19, 0, 1.42), "l_elbow": (0.21, 0, 1.13),
    "l_wrist": (0.23, 0.02, 0.88), "l_hand": (0.235, 0.03, 0.82), "l_handtip": (0.24, 0.04, 0.70),
    "l_thumb": (0.22, 0.08, 0.83),
}


def body_point(key: str, facing_deg: float) -> np.ndarray:
    """World position (Z up) of a BODY point for a body facing ``facing_deg`` from +X."""
    if key.startswith("r_"):
        x, y, z = BODY["l_" + key[2:]]
        x = -x
    else:
        x, y, z = BODY[key]
    a = np.radians(facing_deg)
    fwd = np.array([np.cos(a), np.sin(a), 0.0])
    left = np.array([-np.sin(a), np.cos(a), 0.0])
    return x * left + y * fwd + np.array([0, 0, z])


def tracker_motion(joints, facing_deg=30.0, frames=4) -> Motion:
    """``joints``: ``[(name, parent name or None, BODY key), ...]`` in parent-first order."""
    names = [n for n, _, _ in joints]
    parents = np.array([-1 if p is None else names.index(p) for _, p, _ in joints])
    pos = np.array([body_point(k, facing_deg) for _, _, k in joints])
    rng = np.random.default_rng(1)
    P = pos[None] + rng.normal(0, 0.003, (frames, len(names), 3))
    skel = Skeleton(tuple(names), parents, np.zeros((len(names), 3)))  # trackers give no offsets
    return Motion(skel, 30.0, positions=P)


def _sided(names_fmt, parent_fmt, key):
    out = []
    for side, s, S in (("Left", "l", "LEFT"), ("Right", "r", "RIGHT")):
        out.append((names_fmt.format(side=side, SIDE=S, s=s),
                    None if parent_fmt is None else parent_fmt.format(side=side, SIDE=S, s=s),
                    key.replace("l_", f"{s}_")))
    return out


def kinect_v2_joints():
    j = [("SpineBase", None, "pelvis"), ("SpineMid", "SpineBase", "t12"),
         ("SpineShoulder", "SpineMid", "neck_base"), ("Neck", "SpineShoulder", "mid_neck"),
         ("Head", "Neck", "head_c")]
    for n, p, k in [("Shoulder{side}", "SpineShoulder", "l_shoulder"), ("Elbow{side}", "Shoulder{side}", "l_elbow"),
                    ("Wrist{side}", "Elbow{side}", "l_wrist"), ("Hand{side}", "Wrist{side}", "l_hand"),
                    ("HandTip{side}", "Hand{side}", "l_handtip"), ("Thumb{side}", "Wrist{side}", "l_thumb"),
                    ("Hip{side}", "SpineBase", "l_hip"), ("Knee{side}", "Hip{side}", "l_knee"),
                    ("Ankle{side}", "Knee{side}", "l_ankle"), ("Foot{side}", "Ankle{side}", "l_ball")]:
        j += _sided(n, p, k)
    return j


def azure_joints():
    j = [("K4ABT_JOINT_PELVIS", None, "pelvis"), ("K4ABT_JOINT_SPINE_NAVEL", "K4ABT_JOINT_PELVIS", "navel"),
         ("K4ABT_JOINT_SPINE_CHEST", "K4ABT_JOINT_SPINE_NAVEL", "chest"),
         ("K4ABT_JOINT_NECK", "K4ABT_JOINT_SPINE_CHEST", "neck_base"),
         ("K4ABT_JOINT_HEAD", "K4ABT_JOINT_NECK", "head_c"), ("K4ABT_JOINT_NOSE", "K4ABT_JOINT_HEAD", "nose")]
    P = "K4ABT_JOINT_"
    for n, p, k in [("CLAVICLE_{SIDE}", "SPINE_CHEST", "l_sc"), ("SHOULDER_{SIDE}", "CLAVICLE_{SIDE}", "l_shoulder"),
                    ("ELBOW_{SIDE}", "SHOULDER_{SIDE}", "l_elbow"), ("WRIST_{SIDE}", "ELBOW_{SIDE}", "l_wrist"),
                    ("HAND_{SIDE}", "WRIST_{SIDE}", "l_hand"), ("HANDTIP_{SIDE}", "HAND_{SIDE}", "l_handtip"),
                    ("THUMB_{SIDE}", "WRIST_{SIDE}", "l_thumb"), ("HIP_{SIDE}", "PELVIS", "l_hip"),
                    ("KNEE_{SIDE}", "HIP_{SIDE}", "l_knee"), ("ANKLE_{SIDE}", "KNEE_{SIDE}", "l_ankle"),
                    ("FOOT_{SIDE}", "ANKLE_{SIDE}", "l_ball"), ("EYE_{SIDE}", "HEAD", "l_eye"),
                    ("EAR_{SIDE}", "HEAD", "l_ear")]:
        j += _sided(P + n, P + p, k)
    return j


def openni_joints():
    j = [("torso", None, "t12"), ("neck", "torso", "neck_base"), ("head", "neck", "head_c")]
    for n, p, k in [("{side}_shoulder", "neck", "l_shoulder"), ("{side}_elbow", "{side}_shoulder", "l_elbow"),
                    ("{side}_hand", "{side}_elbow", "l_wrist"), ("{side}_hip", "torso", "l_hip"),
                    ("{side}_knee", "{side}_hip", "l_knee"), ("{side}_foot", "{side}_knee", "l_ankle")]:
        j += _sided(n.replace("{side}", "{side}").lower() if False else n, p, k)
    return [(n.lower(), None if p is None else p.lower(), k) for n, p, k in j]


def smpl_joints():
    j = [("pelvis", None, "pelvis")]
    j += _sided("{side}_hip", "pelvis", "l_hip")
    j += [("spine1", "pelvis", "navel")]
    j += _sided("{side}_knee", "{side}_hip", "l_knee")
    j += [("spine2", "spine1", "t12")]
    j += _sided("{side}_ankle", "{side}_knee", "l_ankle")
    j += [("spine3", "spine2", "chest")]
    j += _sided("{side}_foot", "{side}_ankle", "l_ball")
    j += [("neck", "spine3", "neck_base")]
    j += _sided("{side}_collar", "spine3", "l_sc")
    j += [("head", "neck", "c1")]
    j += _sided("{side}_shoulder", "{side}_collar", "l_shoulder")
    j += _sided("{side}_elbow", "{side}_shoulder", "l_elbow")
    j += _sided("{side}_wrist", "{side}_elbow", "l_wrist")
    j += _sided("{side}_hand", "{side}_wrist", "l_hand")
    return [(n.lower(), None if p is None else p.lower(), k) for n, p, k in j]


def _both(fmt_pairs):
    out = {}
    for c, fmt in fmt_pairs.items():
        for side, S in (("left", "Left"), ("right", "Right")):
            out[f"{side}_{c}"] = fmt.format(side=S, SIDE=S.upper(), s=side)
    return out


TRACKERS = {
    "kinect_v2": (kinect_v2_joints, {
        "pelvis": "SpineBase", "chest": "SpineMid", "neck": "SpineShoulder", "head": "Head",
        **_both({"shoulder": "Shoulder{side}", "elbow": "Elbow{side}", "wrist": "Wrist{side}",
                 "hand_end": "Hand{side}", "hip": "Hip{side}", "knee": "Knee{side}",
                 "ankle": "Ankle{side}", "toe": "Foot{side}"})}),
    "azure_kinect": (azure_joints, {
        "pelvis": "K4ABT_JOINT_PELVIS", "spine": "K4ABT_JOINT_SPINE_NAVEL",
        "chest": "K4ABT_JOINT_SPINE_CHEST", "neck": "K4ABT_JOINT_NECK", "head": "K4ABT_JOINT_HEAD",
        **_both({"clavicle": "K4ABT_JOINT_CLAVICLE_{SIDE}", "shoulder": "K4ABT_JOINT_SHOULDER_{SIDE}",
                 "elbow": "K4ABT_JOINT_ELBOW_{SIDE}", "wrist": "K4ABT_JOINT_WRIST_{SIDE}",
                 "hand_end": "K4ABT_JOINT_HAND_{SIDE}", "hip": "K4ABT_JOINT_HIP_{SIDE}",
                 "knee": "K4ABT_JOINT_KNEE_{SIDE}", "ankle": "K4ABT_JOINT_ANKLE_{SIDE}",
                 "toe": "K4ABT_JOINT_FOOT_{SIDE}"})}),
    "openni": (openni_joints, {
        "pelvis": "midpoint of left_hip and right_hip", "chest": "torso", "neck": "neck", "head": "head",
        **_both({"shoulder": "{s}_shoulder", "elbow": "{s}_elbow", "wrist": "{s}_hand",
                 "hip": "{s}_hip", "knee": "{s}_knee", "ankle": "{s}_foot"})}),
    "smpl": (smpl_joints, {
        "pelvis": "pelvis", "spine": "spine1", "chest": "spine2", "neck": "neck", "head": "head",
        **_both({"clavicle": "{s}_collar", "shoulder": "{s}_shoulder", "elbow": "{s}_elbow",
                 "wrist": "{s}_wrist", "hand_end": "{s}_hand", "hip": "{s}_hip", "knee": "{s}_knee",
                 "ankle": "{s}_ankle", "toe": "{s}_foot"})}),
}


@pytest.mark.parametrize("tracker", sorted(TRACKERS))
@pytest.mark.parametrize("facing", [-90.0, 30.0, 180.0])
def test_tracker_skeletons(tracker, facing):
    make, expected = TRACKERS[tracker]
    motion = tracker_motion(make(), facing)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        jm = map_skeleton(motion)
    assert jm.profile == tracker
    assert names_of(jm) == expected
    pos, mask = canonical_positions(motion, jm)
    assert pos.shape == (motion.num_frames, len(CANONICAL_NAMES), 3)
    assert mask.sum() == len(expected)
    for c in expected:
        assert np.all(np.isfinite(pos[:, CANONICAL_NAMES.index(c)])), c
    # left really is the body's left (up x forward)
    a = np.radians(facing)
    left = np.array([-np.sin(a), np.cos(a), 0.0])
    for stem in ("hip", "shoulder", "knee", "wrist"):
        d = pos[:, CANONICAL_NAMES.index(f"left_{stem}")] - pos[:, CANONICAL_NAMES.index(f"right_{stem}")]
        assert np.all(d @ left > 0.1), stem


def test_tracker_without_hierarchy_and_with_occlusions():
    """A positional file may give no parents and lose joints in some frames."""
    motion = tracker_motion(kinect_v2_joints(), 75.0, frames=9)
    P = motion.positions.copy()
    P[::2, 5:9] = np.nan  # left arm occluded in every other frame
    flat = Skeleton(motion.skeleton.names, np.full(motion.skeleton.num_joints, -1),
                    np.zeros((motion.skeleton.num_joints, 3)))
    jm = map_skeleton(Motion(flat, 30.0, positions=P))
    assert jm.profile == "kinect_v2"
    assert names_of(jm) == TRACKERS["kinect_v2"][1]


def test_unreal_mannequin():
    arm = chain([("clavicle_l", (3, 15, 0)), ("upperarm_l", (15, 0, 0)),
                 ("lowerarm_l", (28, 0, 0), ), ("hand_l", (26, 0, 0)), ("middle_01_l", (10, 0, 0))], (8, 0, 0))
    arm = (arm[0], arm[1], arm[2] + [("upperarm_twist_01_l", (0, 0, 0), [])])
    leg = chain([("thigh_l", (9, -2, 0)), ("calf_l", (0, -43, 0)), ("foot_l", (0, -42, 0)),
                 ("ball_l", (0, -6, 13))], (0, 0, 6))
    top = ("spine_03", (0, 13, 0), [chain([("neck_01", (0, 14, 0)), ("head", (0, 10, 0))], (0, 18, 0)),
                                    arm, mirror(arm)])
    ue = build(("root", (0, 0, 0), [("pelvis", (0, 97, 0), [
        chain([("spine_01", (0, 10, 0)), ("spine_02", (0, 12, 0))], [top]), leg, mirror(leg)]),
        ("ik_foot_root", (0, 0, 0), [])]))
    jm = map_skeleton(ue)
    assert jm.profile == "unreal"
    n = names_of(jm)
    assert (n["pelvis"], n["neck"], n["left_shoulder"], n["right_elbow"], n["left_hand_end"],
            n["right_knee"], n["left_toe"]) == ("pelvis", "neck_01", "upperarm_l", "lowerarm_r",
                                                "middle_01_l", "calf_r", "ball_l")
    assert_sides(jm, ue, ue.rest_positions())


def test_openni_pelvis_is_the_midpoint_of_the_hips():
    motion = tracker_motion(openni_joints(), 0.0)
    jm = map_skeleton(motion)
    assert "pelvis" not in jm.indices and "pelvis" in jm.derived
    pos, mask = canonical_positions(motion, jm)
    P = motion.positions
    names = motion.skeleton.names
    mid = 0.5 * (P[:, names.index("left_hip")] + P[:, names.index("right_hip")])
    np.testing.assert_allclose(pos[:, CANONICAL_NAMES.index("pelvis")], mid)
    conf = canonical_confidence(motion, jm)
    assert conf.shape == (motion.num_frames, len(CANONICAL_NAMES))
    assert np.all(conf[:, mask] == 1.0) and np.all(conf[:, ~mask] == 0.0)
    with pytest.raises(ValueError, match="positional"):
        canonical_rotations(motion, jm)


# ---------------------------------------------------------------------------
# rules


def _view_of(skel):
    return SkeletonView(skel, skel.rest_positions())


def test_spine_chest_rule_by_position():
    motion = load_motion(FIXTURES / "xsens_mvn.bvh")
    v = _view_of(motion.skeleton)
    n = motion.skeleton.names
    got = spine_chest(v, n.index("Hips"), n.index("Neck"), set())
    assert {k: n[j] for k, j in got.items()} == {"spine": "Chest2", "chest": "Chest3"}
    # joints already used are skipped
    got = spine_chest(v, n.index("Hips"), n.index("Neck"), {n.index("Chest3")})
    assert {k: n[j] for k, j in got.items()} == {"spine": "Chest2", "chest": "Chest4"}
    # a single joint low on the chain is the lumbar spine, high up the chest
    low = build(chain([("P", (0, 100, 0)), ("S", (0, 12, 0)), ("N", (0, 38, 0))], (0, 20, 0)))
    assert spine_chest(_view_of(low), 0, 2, set()) == {"spine": 1}
    high = build(chain([("P", (0, 100, 0)), ("S", (0, 35, 0)), ("N", (0, 15, 0))], (0, 20, 0)))
    assert spine_chest(_view_of(high), 0, 2, set()) == {"chest": 1}


def test_left_right_swap_is_reported():
    """A CMU skeleton whose Left/Right names sit on the wrong sides gets a warning."""
    skel = load_motion(shared_file("cmu_12_01_walk.bvh")).skeleton
    swapped = tuple(
        n.replace("Left", "#").replace("Right", "Left").replace("#", "Right")
        .replace("LHip", "#").replace("RHip", "LHip").replace("#", "RHip")
        .replace("LThumb", "#").replace("RThumb", "LThumb").replace("#", "RThumb")
        for n in skel.names)
    bad = Skeleton(swapped, skel.parents, skel.offsets, skel.end_site)
    with pytest.warns(PhysmocapWarning, match="left and right look swapped"):
        map_skeleton(bad, source="swapped.bvh")


def test_missing_arms_error_lists_missing_joints_and_offered_names():
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    skel = motion.skeleton
    arms = set()
    for side in ("LeftShoulder", "RightShoulder"):
        j = skel.index(side)
        arms |= {k for k in range(skel.num_joints) if j in skel.chain(k)}
    armless = skel.subset([k for k in range(skel.num_joints) if k not in arms])
    with pytest.raises(MappingError) as err:
        map_skeleton(armless, source="armless.bvh")
    msg = str(err.value)
    assert msg.startswith("armless.bvh: ")
    missing = re.search(r"joint\(s\) ([a-z_, ]+) \(", msg).group(1).split(", ")
    assert missing == ["left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
                       "left_wrist", "right_wrist"]
    for offered in ("Hips", "LHipJoint", "LeftUpLeg", "Spine1", "Neck1", "Head"):
        assert offered in msg
    assert "LeftArm" not in msg
    # inspecting still works: detect_profile never raises for missing joints
    jm = detect_profile(armless)
    assert set(jm.missing()) == set(missing)
    assert jm.indices["left_knee"] == armless.index("LeftLeg")


# ---------------------------------------------------------------------------
# user mapping files


def test_user_mapping_overrides(tmp_path):
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    path = tmp_path / "cmu.map.toml"
    path.write_text(
        'profile = "cmu"\n'
        "[joints]\n"
        'neck = "Neck"              # the zero-length neck joint instead of Neck1\n'
        'left_hand_end = ["NoSuchJoint", "lefthand index 1"]   # first present, normalised\n'
        "head_end = false\n"
    )
    jm = map_skeleton(motion, mapping=path)
    n = names_of(jm)
    assert jm.profile == "custom" and jm.based_on == "cmu"
    assert n["neck"] == "Neck" and n["left_hand_end"] == "LeftHandIndex1"
    assert "head_end" not in n
    assert n["head"] == "Head" and n["left_wrist"] == "LeftHand"
    # a dict works the same; taking a joint the profile gave to another canonical joint
    # makes the profile fall back to its next candidate (CMU neck: Neck1, then Neck)
    jm2 = map_skeleton(motion, mapping={"joints": {"head": "Neck1"}})
    assert names_of(jm2)["head"] == "Neck1" and names_of(jm2)["neck"] == "Neck"
    assert jm2.profile == "custom" and jm2.based_on == "cmu"


def test_user_mapping_alone_with_profile_none():
    motion = load_motion(shared_file("optitrack_hops_crouch.bvh"))
    entries = {c: n for c, n in names_of(map_skeleton(motion)).items()}
    jm = map_skeleton(motion, profile="none", mapping=entries)
    assert names_of(jm) == entries
    with pytest.raises(MappingError, match="left_knee"):
        map_skeleton(motion, profile="none", mapping={k: v for k, v in entries.items() if k != "left_knee"})


def test_emitted_toml_round_trips(tmp_path):
    motion = load_motion(shared_file("pymo_walk.bvh"))
    jm = map_skeleton(motion)
    path = tmp_path / "pymo.toml"
    path.write_text(jm.to_toml())
    again = map_skeleton(motion, mapping=path)
    assert dict(again.indices) == dict(jm.indices)


@pytest.mark.parametrize(
    "text, error, pattern, line",
    [
        ("[joints]\nleft_wrist = \n", InputError, r"not valid TOML", 2),
        ('[joints]\nneck = "Neck"\nleft_writs = "LeftHand"\n', MappingError,
         r"entry 'left_writs' is not a canonical joint \(did you mean left_wrist[ )].*\. Canonical", 3),
        ('[joints]\nleft_wrist = 3\n', MappingError, r"entry 'left_wrist' = 3: expected a source joint name", 2),
        ('[joints]\nleft_wrist = "LeftHnd"\n', MappingError,
         r"entry left_wrist = 'LeftHnd': the skeleton has no such joint \(did you mean 'LeftHand'[ )].*\. "
         r"Its joints: Hips, LHipJoint", 2),
        ('profile = "cmuu"\n', MappingError, r"entry 'profile' = 'cmuu': expected one of", 1),
        ('[joints]\nleft_wrist = "LeftHand"\nright_wrist = "LeftHand"\n', MappingError,
         r"already mapped to left_wrist", 3),
        ('joints = 5\n', MappingError, r"\[joints\] must be a table", 1),
    ],
)
def test_bad_mapping_files_name_file_line_and_entry(tmp_path, text, error, pattern, line):
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(error) as err:
        map_skeleton(motion, mapping=path)
    assert re.search(pattern, str(err.value)), str(err.value)
    assert str(err.value).startswith(f"{path}:{line}: ")


def test_missing_mapping_file_and_unknown_profile(tmp_path):
    with pytest.raises(InputError, match="mapping file not found"):
        load_mapping_file(tmp_path / "nope.toml")
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    with pytest.raises(OptionError, match="unknown skeleton profile 'mixamoo' \\(did you mean mixamo"):
        map_skeleton(motion, profile="mixamoo")


def test_forced_profile_that_does_not_fit():
    motion = load_motion(shared_file("cmu_12_01_walk.bvh"))
    with pytest.raises(MappingError, match=r"joint\(s\) left_elbow, right_elbow, left_wrist.*tried profile xsens"):
        map_skeleton(motion, profile="xsens")


# ---------------------------------------------------------------------------
# canonical motion


def test_canonical_positions_and_rotations_of_a_recording():
    motion = load_motion(shared_file("cmu_12_01_walk.bvh")).slice_frames(0, 40)
    jm = map_skeleton(motion)
    world, wrot = motion.forward_kinematics()
    pos, mask = canonical_positions(motion, jm)
    rot, rmask = canonical_rotations(motion, jm)
    assert mask.all() and rmask.all()
    for c, j in jm.indices.items():
        k = CANONICAL_NAMES.index(c)
        np.testing.assert_array_equal(pos[:, k], world[:, j])
        np.testing.assert_array_equal(rot[:, k], wrot[:, j])
    rest, rmask2 = canonical_rest_positions(motion.skeleton, jm)
    np.testing.assert_allclose(rest[CANONICAL_NAMES.index("left_knee")],
                               motion.skeleton.rest_positions()[motion.skeleton.index("LeftLeg")])
    # pymo has no chest/head: NaN rows, False mask
    pm = load_motion(shared_file("pymo_walk.bvh")).slice_frames(0, 5)
    pj = map_skeleton(pm)
    p, m = canonical_positions(pm, pj)
    for c in ("chest", "head"):
        k = CANONICAL_NAMES.index(c)
        assert not m[k] and np.all(np.isnan(p[:, k]))
    with pytest.raises(ValueError, match="other joint names"):
        canonical_positions(pm, jm)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), flip=st.booleans())
def test_topology_is_stable_under_renaming_and_turning(seed, flip):
    """Any names, any facing: the shape finds the same joints, sides by geometry."""
    skel = load_motion(FIXTURES / "xsens_mvn.bvh").skeleton
    rng = np.random.default_rng(seed)
    names = tuple(f"b{k}" for k in rng.permutation(skel.num_joints))
    R = Rotation.from_euler("z", rng.uniform(0, 360), degrees=True).as_matrix()
    off = skel.offsets @ R.T
    if flip:  # mirror the body and swap which names are where: sides must follow geometry
        off = off * np.array([1.0, -1.0, 1.0])
    jm = map_skeleton(Skeleton(names, skel.parents, off, skel.end_site))
    ref = map_skeleton(skel)
    expected = dict(ref.indices)
    if flip:
        expected = {
            (c.replace("left_", "#").replace("right_", "left_").replace("#", "right_")): j
            for c, j in expected.items()
        }
    assert dict(jm.indices) == expected
