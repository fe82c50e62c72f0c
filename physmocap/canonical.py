"""The canonical joint set: the joints the retargeter targets.

Every source skeleton is mapped onto these names (``physmocap.sources.profiles``)
and every character ties them to its own sites or bodies (``physmocap.models``).
Positions are joint *centres* (the point a goniometer's axis passes through);
``*_end`` joints are segment tips (end of the hand, tip of the toes, top of
the head).

The table lists each joint's canonical parent (the segment it ends), its side,
and whether a source or character must provide it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "CanonicalJoint",
    "CANONICAL_JOINTS",
    "CANONICAL_NAMES",
    "REQUIRED_JOINTS",
    "canonical_parent",
    "mirror_name",
    "LIMB_END_JOINTS",
]


@dataclass(frozen=True)
class CanonicalJoint:
    name: str
    parent: str | None
    side: str  # "left", "right" or "center"
    required: bool
    description: str


def _sided(
    stem: str, parent_stem: str | None, required: bool, description: str
) -> list[CanonicalJoint]:
    out = []
    for side in ("left", "right"):
        if parent_stem is None:
            parent = None
        elif parent_stem in _CENTER:
            parent = parent_stem
        else:
            parent = f"{side}_{parent_stem}"
        out.append(CanonicalJoint(f"{side}_{stem}", parent, side, required, description))
    return out


_CENTER = {"pelvis", "spine", "chest", "neck", "head"}

CANONICAL_JOINTS: tuple[CanonicalJoint, ...] = tuple(
    [
        CanonicalJoint("pelvis", None, "center", True, "pelvis / root: centre between the hip joints"),
        CanonicalJoint("spine", "pelvis", "center", False, "lumbar spine joint (L5/S1 to L3 region)"),
        CanonicalJoint("chest", "spine", "center", False, "thoracic spine joint (T12/L1 region)"),
        CanonicalJoint("neck", "chest", "center", True, "base of the neck (C7/T1)"),
        CanonicalJoint("head", "neck", "center", False, "head joint (atlanto-occipital, C0/C1)"),
        CanonicalJoint("head_end", "head", "center", False, "top of the head"),
    ]
    + _sided("clavicle", "chest", False, "sterno-clavicular joint")
    + _sided("shoulder", "clavicle", True, "gleno-humeral joint centre")
    + _sided("elbow", "shoulder", True, "elbow joint centre")
    + _sided("wrist", "elbow", True, "wrist joint centre")
    + _sided("hand_end", "wrist", False, "end of the hand (middle finger knuckle or tip)")
    + _sided("hip", "pelvis", True, "hip joint centre")
    + _sided("knee", "hip", True, "knee joint centre")
    + _sided("ankle", "knee", True, "ankle joint centre")
    + _sided("toe", "ankle", False, "ball of the foot (metatarsophalangeal joint)")
    + _sided("toe_end", "toe", False, "tip of the toes")
)

CANONICAL_NAMES: tuple[str, ...] = tuple(j.name for j in CANONICAL_JOINTS)
REQUIRED_JOINTS: tuple[str, ...] = tuple(j.name for j in CANONICAL_JOINTS if j.required)

#: Joints at the end of a chain, usually BVH end sites.
LIMB_END_JOINTS: tuple[str, ...] = (
    "head_end",
    "left_hand_end",
    "right_hand_end",
    "left_toe_end",
    "right_toe_end",
)

_BY_NAME = {j.name: j for j in CANONICAL_JOINTS}


def canonical_parent(name: str, present: set[str] | None = None) -> str | None:
    """Canonical parent of ``name``; with ``present``, the nearest present ancestor.

    A shoulder's parent is the clavicle, but when a skeleton has no clavicle the
    nearest present ancestor is the chest (or the spine, or the pelvis).
    """
    parent = _BY_NAME[name].parent
    if present is None:
        return parent
    while parent is not None and parent not in present:
        parent = _BY_NAME[parent].parent
    return parent


def mirror_name(name: str) -> str:
    """``left_knee`` <-> ``right_knee``; centre joints map to themselves."""
    if name.startswith("left_"):
        return "right_" + name[5:]
    if name.startswith("right_"):
        return "left_" + name[6:]
    return name
