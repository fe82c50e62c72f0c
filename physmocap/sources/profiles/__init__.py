"""Source skeletons onto the canonical joints: vendor profiles, detection, user maps.

The retargeter tracks the canonical joints of :mod:`physmocap.canonical`
(joint *centres*).  This package says which joint of a source skeleton is
each of them::

    from physmocap.sources import load_motion
    from physmocap.sources.profiles import map_skeleton, canonical_positions

    motion = load_motion("clip.bvh")
    jmap = map_skeleton(motion)                 # detect; or profile="cmu", mapping="my.toml"
    jmap.indices                                # {"pelvis": 0, "left_hip": 2, ...}
    pos, mask = canonical_positions(motion, jmap)   # (F, N, 3) in CANONICAL_NAMES order

How a mapping is made (:func:`map_skeleton`):

1. **Profile.**  A built-in naming convention (:data:`PROFILES`: CMU, CMU
   ASF, OptiTrack, Vicon, MotionBuilder, Mixamo, LAFAN1, Perception Neuron,
   PyMO, Xsens, MocapBank, Xsens MVNX, Biovision, Bandai Namco, Daz, Biped,
   Unity, Unreal, SMPL, OpenNI, Kinect v1/v2, Azure Kinect, generic), chosen by the
   caller or detected from the names (:mod:`.mapping`); names are compared
   ignoring case, separators and tool prefixes (:mod:`.names`).
2. **Shape**, when no profile knows the names (:mod:`.topology`).
3. **User mapping file** entries override (:mod:`.mapfile`).
4. **Rules** fill what is left (:mod:`.rules`): spine and chest by position
   along the spine chain, segment tips from end sites, a lone head joint as
   the neck, a missing pelvis as the midpoint of the hips.

A :class:`MappingError` lists the required canonical joints that could not
be mapped and the joint names the skeleton offers.
"""

from __future__ import annotations

from ...errors import MappingError
from .jointmap import (
    JointMap,
    canonical_confidence,
    canonical_positions,
    canonical_rest_positions,
    canonical_rotations,
)
from .mapfile import check_mapping, load_mapping_file
from .mapping import detect_profile, map_skeleton, rank_profiles
from .names import normalize_name, skeleton_keys
from .rules import CHEST_FRACTION, SPINE_FRACTION
from .tables import PROFILES, Profile, profile_names

__all__ = [
    "Profile",
    "PROFILES",
    "profile_names",
    "JointMap",
    "MappingError",
    "normalize_name",
    "skeleton_keys",
    "detect_profile",
    "map_skeleton",
    "rank_profiles",
    "load_mapping_file",
    "check_mapping",
    "canonical_positions",
    "canonical_rotations",
    "canonical_rest_positions",
    "canonical_confidence",
    "SPINE_FRACTION",
    "CHEST_FRACTION",
]
