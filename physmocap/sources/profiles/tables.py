"""Built-in naming profiles: which vendor joint is which canonical joint.

A :class:`Profile` lists, for each canonical joint, the source joint names
that *are* that joint (compared with :func:`~.names.normalize_name`, first
present wins).  Canonical joints are joint **centres**
(:mod:`physmocap.canonical`), so each vendor joint maps to the canonical joint
whose centre it sits at, which is not always the one its name suggests:

* MotionBuilder-style names (CMU, OptiTrack, Vicon, Mixamo, LAFAN1, Perception
  Neuron, HumanIK) name the *segment that starts* at a joint: ``LeftShoulder``
  is the clavicle (sterno-clavicular joint), ``LeftArm`` the shoulder,
  ``LeftForeArm`` the elbow, ``LeftHand`` the wrist, ``LeftUpLeg`` the hip,
  ``LeftLeg`` the knee, ``LeftFoot`` the ankle, ``LeftToeBase`` the ball of
  the foot.  CMU's ``LHipJoint`` starts the pelvis-to-hip bone *at the
  pelvis* and maps to nothing; its ``Neck`` sits on ``Spine1`` (a zero-length
  bone), so the neck base is ``Neck1``.
* Xsens MVN and MocapBank BVH name joints: ``LeftShoulder`` *is* the shoulder
  (``LeftCollar`` the clavicle), ``LeftHip`` the hip.
* Segment-named conventions (Unity, Bandai Namco, Xsens MVNX, Daz, Biped)
  follow the segment rule: ``LeftUpperArm`` / ``UpperArm_L`` / ``lShldr`` /
  ``L UpperArm`` start at the shoulder.
* Trackers (OpenNI, Kinect, Azure Kinect, SMPL) report joint centres directly.

Canonical joints left out of a profile are filled by rules in
:mod:`.mapping`: ``spine`` and ``chest`` by position along the spine chain,
``*_end`` by the end site below the last mapped joint, a missing ``neck`` by
a lone head joint, and a missing ``pelvis`` by the midpoint of the hips.
Optional joints a source does not have stay unmapped.

Name templates: ``{side}`` becomes ``Left`` / ``Right`` and ``{s}`` becomes
``L`` / ``R`` (case does not matter after normalisation).  Keys of a profile
table without a ``left_`` / ``right_`` prefix and not a centre joint are
expanded to both sides.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

from ...canonical import CANONICAL_NAMES
from .names import normalize_name

__all__ = ["Profile", "PROFILES", "profile_names"]

_CENTER = ("pelvis", "spine", "chest", "neck", "head", "head_end")
_SIDES = (("left", "Left", "L"), ("right", "Right", "R"))


@dataclass(frozen=True)
class Profile:
    """A vendor naming convention.

    Attributes:
        name: Short identifier (``"cmu"``), used by ``--profile``.
        description: One line for people.
        joints: Canonical joint -> candidate source names in preference order
            (any of them, compared after :func:`~.names.normalize_name`).
        signature: Other names typical of the convention; they only help
            :func:`~.mapping.detect_profile` tell similar conventions apart.
        prefixes: Tool prefixes typical of the convention (as reported by
            :func:`~.names.skeleton_keys`, e.g. ``"mixamorig"``).
        source: Where the joint names come from.
    """

    name: str
    description: str
    joints: Mapping[str, tuple[str, ...]]
    signature: tuple[str, ...] = ()
    prefixes: tuple[str, ...] = ()
    source: str = ""
    keys: frozenset[str] = field(default=frozenset(), repr=False, compare=False)

    def __post_init__(self) -> None:
        for c in self.joints:
            if c not in CANONICAL_NAMES:
                raise ValueError(f"profile {self.name!r}: {c!r} is not a canonical joint")
        allk = {normalize_name(n) for names in self.joints.values() for n in names}
        allk |= {normalize_name(n) for n in self.signature}
        object.__setattr__(self, "keys", frozenset(allk))
        object.__setattr__(self, "joints", MappingProxyType(dict(self.joints)))


def _expand(template: str, side: tuple[str, str, str]) -> str:
    _, word, letter = side
    return template.replace("{side}", word).replace("{s}", letter)


def _profile(
    name: str,
    description: str,
    source: str,
    *,
    signature: tuple[str, ...] = (),
    prefixes: tuple[str, ...] = (),
    **entries: tuple[str, ...],
) -> Profile:
    joints: dict[str, tuple[str, ...]] = {}
    for key, names in entries.items():
        if key in _CENTER:
            joints[key] = tuple(names)
        else:
            for side in _SIDES:
                joints[f"{side[0]}_{key}"] = tuple(_expand(n, side) for n in names)
    sig: list[str] = []
    for n in signature:
        if "{side}" in n or "{s}" in n:
            sig.extend(_expand(n, s) for s in _SIDES)
        else:
            sig.append(n)
    return Profile(name, description, joints, tuple(sig), prefixes, source)


def _generic_forms(*stems: str) -> tuple[str, ...]:
    """``left_knee``, ``l_knee``, ``knee_left``, ``knee_l`` for each stem."""
    out: list[str] = []
    for stem in stems:
        out += [f"{{side}}_{stem}", f"{{s}}_{stem}", f"{stem}_{{side}}", f"{stem}_{{s}}"]
    return tuple(out)


# MotionBuilder-style limb names, shared by several conventions.
_MB_ARM = dict(
    clavicle=("{side}Shoulder",),
    shoulder=("{side}Arm",),
    elbow=("{side}ForeArm",),
    wrist=("{side}Hand",),
)
_MB_LEG = dict(
    hip=("{side}UpLeg",),
    knee=("{side}Leg",),
    ankle=("{side}Foot",),
    toe=("{side}ToeBase",),
)

_LIST: list[Profile] = [
    _profile(
        "cmu",
        "CMU Graphics Lab motion capture database, MotionBuilder-friendly BVH (cgspeed)",
        "hierarchy of the CMU BVH conversions (e.g. ../shared/data/cmu_01_01_jumps.bvh)",
        pelvis=("Hips",),
        neck=("Neck1", "Neck"),
        head=("Head",),
        hand_end=("{s}Fingers", "{side}HandIndex1"),
        **_MB_ARM,
        **_MB_LEG,
        signature=("{s}HipJoint", "LowerBack", "Spine", "Spine1", "{side}FingerBase", "{s}Thumb"),
    ),
    _profile(
        "cmu_asf",
        "CMU database with its ASF bone names (root, lfemur, ltibia, lhumerus, lradius...)",
        "CMU ASF skeleton files (bone names; a bone starts at its proximal joint)",
        pelvis=("root",),
        neck=("lowerneck",),
        head=("head",),
        clavicle=("{s}clavicle",),
        shoulder=("{s}humerus",),
        elbow=("{s}radius",),
        wrist=("{s}wrist",),
        hand_end=("{s}fingers",),
        hip=("{s}femur",),
        knee=("{s}tibia",),
        ankle=("{s}foot",),
        toe=("{s}toes",),
        signature=("{s}hipjoint", "lowerback", "upperback", "thorax", "upperneck", "{s}hand",
                   "{s}thumb"),
    ),
    _profile(
        "optitrack",
        "OptiTrack Motive BVH export (Hips, Spine, Spine1, Neck, Head, MotionBuilder-style limbs)",
        "OptiTrack Motive BVH export (../shared/data/optitrack_hops_crouch.bvh)",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Spine", "Spine1"),
    ),
    _profile(
        "optitrack_motive",
        "OptiTrack Motive skeleton segment names (Hip, Ab, Chest, LShoulder, LUArm, LFArm, LThigh)",
        "Motive skeleton segments (a segment starts at its proximal joint: LUArm at the "
        "shoulder, LThigh at the hip, LToe at the ball of the foot)",
        pelvis=("Hip",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{s}Shoulder",),
        shoulder=("{s}UArm",),
        elbow=("{s}FArm",),
        wrist=("{s}Hand",),
        hip=("{s}Thigh",),
        knee=("{s}Shin",),
        ankle=("{s}Foot",),
        toe=("{s}Toe",),
        signature=("Ab", "Chest"),
        prefixes=("skeleton",),
    ),
    _profile(
        "vicon",
        "Vicon Shogun / Blade skeleton (Spine..Spine3, Neck, Neck1, HumanIK-style limbs)",
        "Vicon Shogun default skeleton names (Neck is the neck base, Neck1 mid-neck)",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        head_end=("HeadEnd", "HeadTop"),
        hand_end=("{side}HandMiddle1", "{side}HandIndex1"),
        toe_end=("{side}ToeBaseEnd", "{side}ToeEnd"),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Spine", "Spine1", "Spine2", "Spine3", "Neck1", "{side}HandThumb1"),
    ),
    _profile(
        "motionbuilder",
        "Autodesk MotionBuilder / HumanIK characters (Character1_ prefix, roll bones)",
        "MotionBuilder HumanIK skeleton naming",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        head_end=("HeadEnd",),
        hand_end=("{side}HandMiddle1", "{side}HandIndex1"),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Reference", "Spine", "Spine1", "Spine2", "Spine3", "Neck1", "{side}ArmRoll",
                   "{side}ForeArmRoll", "{side}UpLegRoll", "{side}LegRoll", "{side}FootMiddle1"),
        prefixes=("character",),
    ),
    _profile(
        "mixamo",
        "Adobe Mixamo rigs (mixamorig: prefix, HeadTop_End, LeftToe_End)",
        "Mixamo character rig joint names",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        head_end=("HeadTop_End",),
        hand_end=("{side}HandMiddle1", "{side}HandIndex1"),
        toe_end=("{side}Toe_End",),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Spine", "Spine1", "Spine2", "{side}HandThumb1", "{side}HandRing1",
                   "{side}HandPinky1", "{side}HandIndex4", "{side}HandMiddle4"),
        prefixes=("mixamorig",),
    ),
    _profile(
        "lafan1",
        "Ubisoft La Forge LAFAN1 animation dataset (22 joints, LeftToe)",
        "LAFAN1 BVH hierarchy (Hips, LeftUpLeg..LeftToe, Spine, Spine1, Spine2, Neck, Head, "
        "LeftShoulder..LeftHand)",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        **_MB_ARM,
        hip=("{side}UpLeg",),
        knee=("{side}Leg",),
        ankle=("{side}Foot",),
        toe=("{side}Toe",),
        signature=("Spine", "Spine1", "Spine2"),
    ),
    _profile(
        "perception_neuron",
        "Noitom Perception Neuron (Axis Neuron / Axis Studio BVH, InHand finger roots)",
        "Axis Neuron BVH export hierarchy",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        hand_end=("{side}HandMiddle1",),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Spine", "Spine1", "Spine2", "Spine3", "Neck1", "{side}InHandIndex",
                   "{side}InHandMiddle", "{side}InHandRing", "{side}InHandPinky",
                   "{side}HandThumb1"),
    ),
    _profile(
        "pymo",
        "PyMO / AV emotional-motion skeleton (single Spine, Head as the neck, LeftHand_End)",
        "omimo/PyMO demo data (../shared/data/pymo_walk.bvh)",
        pelvis=("Hips",),
        neck=("Head",),
        hand_end=("{side}Hand_End",),
        **_MB_ARM,
        **_MB_LEG,
        signature=("Spine", "{side}HandThumb1"),
    ),
    _profile(
        "xsens",
        "Xsens MVN BVH export (Chest..Chest4, LeftCollar, LeftShoulder is the shoulder joint)",
        "Xsens MVN Analyze BVH export hierarchy",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{side}Collar",),
        shoulder=("{side}Shoulder",),
        elbow=("{side}Elbow",),
        wrist=("{side}Wrist",),
        hip=("{side}Hip",),
        knee=("{side}Knee",),
        ankle=("{side}Ankle",),
        toe=("{side}Toe",),
        signature=("Chest", "Chest2", "Chest3", "Chest4"),
    ),
    _profile(
        "mocapbank",
        "MocapBank BVH (Xsens-style joint names, Chest and Chest2, no toes)",
        "MocapBank sample clip (tests/test_mocapbank.bvh of 20tab/bvh-python)",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{side}Collar",),
        shoulder=("{side}Shoulder",),
        elbow=("{side}Elbow",),
        wrist=("{side}Wrist",),
        hip=("{side}Hip",),
        knee=("{side}Knee",),
        ankle=("{side}Ankle",),
        signature=("Chest", "Chest2"),
    ),
    _profile(
        "xsens_mvnx",
        "Xsens MVN segment names (MVNX / MVN exports: Pelvis, L5, L3, T12, T8, RightUpperArm...)",
        "Xsens MVN biomechanical model: a segment starts at its proximal joint (L3 at jL4L3, "
        "T12 at jL1T12, RightUpperArm at jRightShoulder, RightToe at jRightBallFoot)",
        pelvis=("Pelvis",),
        spine=("L3",),
        chest=("T12",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{side}Shoulder",),
        shoulder=("{side}UpperArm",),
        elbow=("{side}ForeArm",),
        wrist=("{side}Hand",),
        hip=("{side}UpperLeg",),
        knee=("{side}LowerLeg",),
        ankle=("{side}Foot",),
        toe=("{side}Toe",),
        signature=("L5", "T8"),
    ),
    _profile(
        "biovision",
        "Classic Biovision BVH (Chest, LeftCollar, LeftUpArm, LeftLowArm, LeftUpLeg, LeftLowLeg)",
        "the Biovision BVH examples (Meredith and Maddock, 'Motion capture file formats "
        "explained', 2001)",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{side}Collar",),
        shoulder=("{side}UpArm",),
        elbow=("{side}LowArm",),
        wrist=("{side}Hand",),
        hip=("{side}UpLeg", "{side}Hip"),
        knee=("{side}LowLeg", "{side}Knee"),
        ankle=("{side}Foot", "{side}Ankle"),
        signature=("Chest",),
    ),
    _profile(
        "bandai_namco",
        "Bandai Namco Research Motiondataset (joint_Root above Hips, Shoulder_L, UpperArm_L...)",
        "BandaiNamcoResearchInc/Bandai-Namco-Research-Motiondataset BVH hierarchy",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("Shoulder_{s}",),
        shoulder=("UpperArm_{s}",),
        elbow=("LowerArm_{s}",),
        wrist=("Hand_{s}",),
        hip=("UpperLeg_{s}",),
        knee=("LowerLeg_{s}",),
        ankle=("Foot_{s}",),
        toe=("Toes_{s}",),
        signature=("joint_Root", "Spine", "Chest"),
    ),
    _profile(
        "daz",
        "Daz 3D / Poser figures (hip, abdomen, chest, lCollar, lShldr, lThigh; Genesis Bend/Twist)",
        "Poser/Daz figure joint names (cgspeed's Daz-friendly CMU release; Genesis 3/8)",
        pelvis=("hip",),
        neck=("neck", "neckLower"),
        head=("head",),
        clavicle=("{s}Collar",),
        shoulder=("{s}Shldr", "{s}ShldrBend"),
        elbow=("{s}ForeArm", "{s}ForearmBend"),
        wrist=("{s}Hand",),
        hand_end=("{s}Mid1",),
        hip=("{s}Thigh", "{s}ThighBend"),
        knee=("{s}Shin",),
        ankle=("{s}Foot",),
        toe=("{s}Toe",),
        signature=("abdomen", "chest", "abdomenLower", "abdomenUpper", "chestLower", "chestUpper",
                   "neckUpper", "pelvis", "{s}Buttock", "{side}Eye", "{s}Eye", "{s}ShldrTwist",
                   "{s}ForearmTwist", "{s}ThighTwist", "{s}Metatarsals", "{s}Thumb1",
                   "{s}Index1"),
    ),
    _profile(
        "biped",
        "Autodesk 3ds Max Biped (Bip01 prefix: Pelvis, L Clavicle, L UpperArm, L Thigh, L Calf)",
        "3ds Max Character Studio Biped naming",
        pelvis=("Pelvis",),
        neck=("Neck",),
        head=("Head",),
        head_end=("HeadNub",),
        clavicle=("{s} Clavicle",),
        shoulder=("{s} UpperArm",),
        elbow=("{s} Forearm",),
        wrist=("{s} Hand",),
        hand_end=("{s} Finger2", "{s} Finger1"),
        hip=("{s} Thigh",),
        knee=("{s} Calf",),
        ankle=("{s} Foot",),
        toe=("{s} Toe0",),
        toe_end=("{s} Toe0Nub",),
        signature=("Spine", "Spine1", "Spine2", "{s} Finger0"),
        prefixes=("bip",),
    ),
    _profile(
        "unity",
        "Unity Humanoid / VRM bone names (Chest, UpperChest, LeftUpperArm, LeftLowerLeg, LeftToes)",
        "Unity HumanBodyBones enumeration",
        pelvis=("Hips",),
        neck=("Neck",),
        head=("Head",),
        clavicle=("{side}Shoulder",),
        shoulder=("{side}UpperArm",),
        elbow=("{side}LowerArm",),
        wrist=("{side}Hand",),
        hand_end=("{side}MiddleProximal",),
        hip=("{side}UpperLeg",),
        knee=("{side}LowerLeg",),
        ankle=("{side}Foot",),
        toe=("{side}Toes",),
        signature=("Spine", "Chest", "UpperChest"),
    ),
    _profile(
        "unreal",
        "Unreal Engine mannequin (pelvis, spine_01.., clavicle_l, upperarm_l, thigh_l, calf_l, ball_l)",
        "Unreal Engine 4/5 mannequin skeleton bone names (a bone starts at its proximal joint)",
        pelvis=("pelvis",),
        neck=("neck_01",),
        head=("head",),
        clavicle=("clavicle_{s}",),
        shoulder=("upperarm_{s}",),
        elbow=("lowerarm_{s}",),
        wrist=("hand_{s}",),
        hand_end=("middle_01_{s}", "middle_metacarpal_{s}"),
        hip=("thigh_{s}",),
        knee=("calf_{s}",),
        ankle=("foot_{s}",),
        toe=("ball_{s}",),
        signature=("root", "spine_01", "spine_02", "spine_03", "spine_04", "spine_05", "neck_02",
                   "upperarm_twist_01_{s}", "lowerarm_twist_01_{s}", "thigh_twist_01_{s}",
                   "calf_twist_01_{s}", "ik_foot_root", "ik_hand_root"),
    ),
    _profile(
        "smpl",
        "SMPL / SMPL-X body joints (pelvis, left_hip, spine1..3, left_collar, left_foot = ball)",
        "SMPL joint list (Loper et al. 2015; SMPL-X, Pavlakos et al. 2019)",
        pelvis=("pelvis",),
        neck=("neck",),
        head=("head",),
        clavicle=("{side}_collar",),
        shoulder=("{side}_shoulder",),
        elbow=("{side}_elbow",),
        wrist=("{side}_wrist",),
        hand_end=("{side}_middle1", "{side}_hand"),
        hip=("{side}_hip",),
        knee=("{side}_knee",),
        ankle=("{side}_ankle",),
        toe=("{side}_foot",),
        signature=("spine1", "spine2", "spine3", "jaw"),
    ),
    _profile(
        "openni",
        "OpenNI / NITE 15-joint tracker skeleton (head, neck, torso, hands, feet; no pelvis)",
        "OpenNI XnSkeletonJoint (XN_SKEL_HEAD ... XN_SKEL_RIGHT_FOOT), NITE2 nite::JointType, "
        "ROS openni_tracker frames; hand and foot stand in for wrist and ankle",
        chest=("torso",),
        neck=("neck",),
        head=("head",),
        clavicle=("{side}_collar",),
        shoulder=("{side}_shoulder",),
        elbow=("{side}_elbow",),
        wrist=("{side}_wrist", "{side}_hand"),
        hand_end=("{side}_fingertip", "{side}_hand"),
        hip=("{side}_hip",),
        knee=("{side}_knee",),
        ankle=("{side}_ankle", "{side}_foot"),
        toe=("{side}_foot",),
        signature=("torso", "waist"),
    ),
    _profile(
        "kinect_v1",
        "Kinect for Windows SDK 1.x skeleton (20 joints: HipCenter, Spine, ShoulderCenter...)",
        "NUI_SKELETON_POSITION_INDEX (Kinect for Windows SDK 1.8)",
        pelvis=("HipCenter",),
        chest=("Spine",),
        neck=("ShoulderCenter",),
        head=("Head",),
        shoulder=("Shoulder{side}",),
        elbow=("Elbow{side}",),
        wrist=("Wrist{side}",),
        hand_end=("Hand{side}",),
        hip=("Hip{side}",),
        knee=("Knee{side}",),
        ankle=("Ankle{side}",),
        toe=("Foot{side}",),
    ),
    _profile(
        "kinect_v2",
        "Kinect for Windows SDK 2.0 body (25 joints: SpineBase, SpineMid, SpineShoulder...)",
        "JointType enumeration (Kinect for Windows SDK 2.0)",
        pelvis=("SpineBase",),
        chest=("SpineMid",),
        neck=("SpineShoulder",),
        head=("Head",),
        shoulder=("Shoulder{side}",),
        elbow=("Elbow{side}",),
        wrist=("Wrist{side}",),
        hand_end=("Hand{side}",),
        hip=("Hip{side}",),
        knee=("Knee{side}",),
        ankle=("Ankle{side}",),
        toe=("Foot{side}",),
        signature=("Neck", "HandTip{side}", "Thumb{side}"),
    ),
    _profile(
        "azure_kinect",
        "Azure Kinect Body Tracking SDK (32 joints: PELVIS, SPINE_NAVEL, SPINE_CHEST, CLAVICLE_LEFT...)",
        "k4abt_joint_id_t (Azure Kinect Body Tracking SDK; learn.microsoft.com "
        "azure/kinect-dk/body-joints)",
        pelvis=("PELVIS",),
        spine=("SPINE_NAVEL", "SPINE_NAVAL"),
        chest=("SPINE_CHEST",),
        neck=("NECK",),
        head=("HEAD",),
        clavicle=("CLAVICLE_{side}",),
        shoulder=("SHOULDER_{side}",),
        elbow=("ELBOW_{side}",),
        wrist=("WRIST_{side}",),
        hand_end=("HAND_{side}",),
        hip=("HIP_{side}",),
        knee=("KNEE_{side}",),
        ankle=("ANKLE_{side}",),
        toe=("FOOT_{side}",),
        signature=("NOSE", "EYE_{side}", "EAR_{side}", "HANDTIP_{side}", "THUMB_{side}"),
    ),
    _profile(
        "generic",
        "Plain joint-centre names (pelvis, left_hip, l_knee, knee_l, LeftAnkle, r_wrist...)",
        "common joint-centre naming; a name ending a chain (hand, foot) is left to the end-site "
        "rule because vendors disagree on what it means",
        pelvis=("pelvis", "hips", "hip_center", "mid_hip", "root"),
        neck=("neck", "neck_base", "lower_neck"),
        head=("head",),
        head_end=("head_top", "head_end", "headtop"),
        clavicle=_generic_forms("clavicle", "collar"),
        shoulder=_generic_forms("shoulder"),
        elbow=_generic_forms("elbow"),
        wrist=_generic_forms("wrist"),
        hip=_generic_forms("hip"),
        knee=_generic_forms("knee"),
        ankle=_generic_forms("ankle"),
        toe=_generic_forms("toe", "ball", "toes"),
        toe_end=_generic_forms("toe_tip", "toe_end"),
    ),
]

#: Built-in profiles by name, in detection tie-break order.
PROFILES: Mapping[str, Profile] = MappingProxyType({p.name: p for p in _LIST})


def profile_names() -> tuple[str, ...]:
    """Names accepted by ``profile=``: the built-ins, ``"topology"`` and ``"none"``."""
    return tuple(PROFILES) + ("topology", "none")
