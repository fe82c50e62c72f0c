"""Joint-name normalisation: compare names across vendors' spelling habits.

Two joint names are *the same* when their normalised forms are equal.
:func:`normalize_name` removes what varies between exports of one skeleton
convention but never carries meaning:

* a namespace: everything up to the last ``:`` or ``|`` (``mixamorig:Hips``,
  ``Take001|Hips``, ``nite::JOINT_HEAD``);
* one known tool prefix followed by a separator: ``mixamorig_``,
  ``Character1_`` (MotionBuilder HumanIK), ``Bip01 `` (3ds Max Biped),
  ``Skeleton001_`` (OptiTrack Motive), ``XN_SKEL_`` (OpenNI),
  ``K4ABT_JOINT_`` (Azure Kinect), ``JointType_`` (Kinect v2), ``JOINT_``
  (NITE 2), ``joint_`` (Bandai Namco);
* case, and the separators ``_ - . : space``.

:func:`skeleton_keys` normalises every joint of a skeleton and also strips a
prefix that *all* joints share (``Model_Hips``, ``Model_Spine``... ->
``hips``, ``spine``...), which covers per-file character names.
"""

from __future__ import annotations

import os
import re
from typing import Sequence

__all__ = ["normalize_name", "skeleton_keys", "SEPARATORS"]

#: Characters ignored when comparing names.
SEPARATORS = "_-.: "

_NAMESPACE = re.compile(r"^.*[:|]")
_PREFIX = re.compile(
    r"^(?P<prefix>mixamorig\d*|character\d*|bip\d+|skeleton[_ ]?\d*|xn_skel|k4abt_joint"
    r"|jointtype|joint)[\s_\-.:]+",
    re.IGNORECASE,
)
_SEPARATOR_RUN = re.compile(r"[\s_\-.:]+")
_SIDE_TOKENS = {"l", "r", "left", "right", "lft", "rt", "rgt"}


def _strip(name: str) -> tuple[str, str]:
    """``(rest, prefix)``: the name without namespace and known prefix."""
    s = str(name).strip()
    prefix = ""
    ns = _NAMESPACE.match(s)
    if ns and ns.end() < len(s):
        prefix = re.sub(r"[\d:|_\s]+$", "", ns.group(0)).lower()
        s = s[ns.end():]
    m = _PREFIX.match(s)
    if m and m.end() < len(s):
        prefix = re.sub(r"[\d_\s]+$", "", m.group("prefix")).lower()
        s = s[m.end():]
    return s, prefix


def normalize_name(name: str) -> str:
    """The comparison key of a joint name (see the module docstring).

    >>> normalize_name("mixamorig:LeftUpLeg"), normalize_name("Bip01 L Thigh")
    ('leftupleg', 'lthigh')
    >>> normalize_name("XN_SKEL_LEFT_HIP"), normalize_name("left-hip")
    ('lefthip', 'lefthip')
    """
    rest, _ = _strip(name)
    key = _SEPARATOR_RUN.sub("", rest).lower()
    return key or _SEPARATOR_RUN.sub("", str(name)).lower()


def _common_prefix(names: Sequence[str]) -> str:
    """A raw prefix shared by all names that ends in a separator, or ``""``."""
    if len(names) < 4:
        return ""
    prefix = os.path.commonprefix(list(names))
    cut = max(prefix.rfind(c) for c in SEPARATORS + "|")
    if cut < 0:
        return ""
    prefix = prefix[: cut + 1]
    if _SEPARATOR_RUN.sub("", prefix).lower() in _SIDE_TOKENS:
        return ""
    if any(len(n) <= len(prefix) for n in names):
        return ""
    return prefix


def skeleton_keys(names: Sequence[str]) -> tuple[list[str], str]:
    """Normalised keys for every joint name and the prefix that was found.

    Returns:
        ``(keys, prefix)``: ``keys[j]`` is the comparison key of ``names[j]``
        after removing a prefix shared by all names (see the module
        docstring); ``prefix`` names the tool prefix or namespace seen on the
        first joint (lower case, digits dropped, e.g. ``"mixamorig"``,
        ``"character"``, ``"bip"``), or ``""``.
    """
    common = _common_prefix(names)
    stripped = [n[len(common):] for n in names] if common else list(names)
    keys = [normalize_name(n) for n in stripped]
    prefix = ""
    if names:
        _, prefix = _strip(names[0])
        if not prefix and common:
            prefix = re.sub(r"[\d_\s:|.\-]+$", "", common).lower()
    return keys, prefix
