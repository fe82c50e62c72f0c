"""Range of motion of every degree of freedom of the default humanoid, as data.

This table is the single source of the default humanoid's joint ranges: the
generator (:mod:`physmocap.models.humanoid_builder`) writes them into
``assets/mjcf/humanoid.xml`` and a test checks that every hinge there has the
range this table gives.

Sources (degrees, active range from the anatomical neutral position: standing,
arms at the sides, palms facing the thighs, feet forward); every value is in
the tables below, with its source:

* ``S1``-``S4``: the four goniometry sources of a 2017 mocap-cleanup study
  (Luttgens, Hamilton and Weimar, *Kinesiology: Scientific Basis of Human
  Motion*, 12th ed., 2011; and a goniometry reference table, AOK Health 2017).
  Where a source gives a span ("60-90") the upper end is stored.
* ``AAOS``: American Academy of Orthopaedic Surgeons figures, for movements
  the four sources lack (ankle inversion and eversion,
  first metatarsophalangeal extension and flexion, knee hyperextension).
* ``NEUMANN``: D. A. Neumann, *Kinesiology of the Musculoskeletal System*,
  2nd ed., 2010, ch. 5, sterno-clavicular joint: elevation 45, depression 10,
  protraction 15-20, retraction 15-30 (upper ends stored).

Policy (where sources differ, and performers exceed them)
---------------------------------------------------------
* ``"strict"`` (clinical): the **median** over the sources that give a value.
* ``"default"``: the **largest** value over the sources **plus a margin** of
  :data:`MARGIN_DEG` (15 degrees), because dancers, martial artists and
  gymnasts exceed clinical ranges and a retargeter must not clip real motion.
  Movements marked ``margin=False`` get no margin: they are anatomical stops
  whose violation is a capture glitch (knee and elbow hyperextension).
* Spine ranges are for a whole region and are split across the model's joints
  by a fixed share (``share``): thoraco-lumbar flexion/extension 60 % lumbar /
  40 % thoracic, lateral flexion 50/50, axial rotation 30/70 (lumbar facets
  allow ~2 degrees of rotation per level, the thoracic spine most of it: White
  and Panjabi, *Clinical Biomechanics of the Spine*, 2nd ed., 1990); cervical
  flexion/extension 75 % neck (C1-C7) / 25 % head (C0/C1), lateral flexion
  80/20, rotation 50/50 (about half of cervical rotation is at C1/C2, which
  the ``head`` joint stands for).
* Left and right are the same entries mirrored: the table stores the **left**
  side (and the centre); :func:`mirror_axis` gives the right side's axis.

Axes and signs
--------------
Every body frame of the default humanoid is aligned with the world in the rest
pose (X forward, Y left, Z up), so each hinge axis below is both a body-frame
and a world-frame axis.  A hinge turns its child by the right-hand rule about
its axis; the axes are chosen so that a **positive angle is the movement named
``positive``** (for example ``left_hip_flexion`` turns about -Y, which swings
the thigh forward).  Mirroring the left side through the sagittal (XZ) plane
maps an axis ``(x, y, z)`` to ``(-x, y, -z)`` with the same sign meaning, so
``right_hip_adduction`` turns about +X where ``left_hip_adduction`` turns
about -X.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MARGIN_DEG",
    "POLICIES",
    "Movement",
    "DofRange",
    "ROM_TABLE",
    "mirror_axis",
    "dof_names",
    "dof_entry",
    "joint_axis",
    "joint_range_deg",
    "joint_ranges_deg",
]

#: Margin added to the largest clinical value under the ``"default"`` policy, degrees.
MARGIN_DEG = 15.0
#: Names of the range policies.
POLICIES = ("default", "strict")


@dataclass(frozen=True)
class Movement:
    """One direction of a degree of freedom and its clinical values.

    Attributes:
        name: clinical name of the movement (``"flexion"``, ``"abduction"``...).
        values: ``{source: degrees}``; sources are ``S1``-``S4``, ``AAOS``, ``NEUMANN``.
        margin: whether the ``"default"`` policy adds :data:`MARGIN_DEG`.
    """

    name: str
    values: dict[str, float]
    margin: bool = True

    def amount(self, policy: str) -> float:
        """Range of this movement in degrees (>= 0) under ``policy``."""
        vals = list(self.values.values())
        if policy == "strict":
            return float(statistics.median(vals))
        if policy == "default":
            return float(max(vals)) + (MARGIN_DEG if self.margin else 0.0)
        raise ValueError(f"unknown range policy {policy!r}; expected one of {POLICIES}")


@dataclass(frozen=True)
class DofRange:
    """One hinge of the default humanoid.

    Attributes:
        stem: joint name without side (``"hip_flexion"``); sided joints are
            named ``left_<stem>`` and ``right_<stem>``.
        sided: True for limb joints (one per side), False for the spine/head.
        axis: hinge axis of the left (or centre) joint, body = world frame at rest.
        positive: movement for positive angles.
        negative: movement for negative angles (its amount is the lower bound).
        share: fraction of the region's range given to this hinge (spine splits).
        group: joint default class in the MJCF (``spine``, ``neck``, ``arm``, ``leg``...).
    """

    stem: str
    sided: bool
    axis: tuple[float, float, float]
    positive: Movement
    negative: Movement
    share: float = 1.0
    group: str = "limb"

    def range_deg(self, policy: str = "default") -> tuple[float, float]:
        """``(lo, hi)`` in degrees under ``policy``."""
        lo = -self.negative.amount(policy) * self.share
        hi = self.positive.amount(policy) * self.share
        return (_clean(lo), _clean(hi))


def _clean(x: float) -> float:
    """Round to 0.1 degree so the MJCF text and the table agree exactly."""
    return round(float(x) + 0.0, 1) + 0.0


def _m(name: str, margin: bool = True, **values: float) -> Movement:
    return Movement(name, dict(values), margin)


# -- the clinical values (sources above) ------------------------------------------
_TL_FLEX = _m("flexion", S1=50, S4=45)
_TL_EXT = _m("extension", S1=25, S4=35)
_TL_LAT = _m("lateral flexion", S1=25, S4=30)
_TL_ROT = _m("rotation", S1=30, S4=45)
_C_FLEX = _m("flexion", S1=60, S4=40)
_C_EXT = _m("extension", S1=75, S4=40)
_C_LAT = _m("lateral flexion", S1=45, S4=45)
_C_ROT = _m("rotation", S1=80, S4=50)

ROM_TABLE: tuple[DofRange, ...] = (
    # spine: flexion about +Y (chest forward), lateral flexion about +X
    # (positive = bending to the right), rotation about +Z (positive = turning left).
    DofRange("lumbar_flexion", False, (0, 1, 0), _TL_FLEX, _TL_EXT, 0.6, "spine"),
    DofRange("lumbar_lateral_flexion", False, (1, 0, 0), _TL_LAT, _TL_LAT, 0.5, "spine"),
    DofRange("lumbar_rotation", False, (0, 0, 1), _TL_ROT, _TL_ROT, 0.3, "spine"),
    DofRange("thoracic_flexion", False, (0, 1, 0), _TL_FLEX, _TL_EXT, 0.4, "spine"),
    DofRange("thoracic_lateral_flexion", False, (1, 0, 0), _TL_LAT, _TL_LAT, 0.5, "spine"),
    DofRange("thoracic_rotation", False, (0, 0, 1), _TL_ROT, _TL_ROT, 0.7, "spine"),
    DofRange("neck_flexion", False, (0, 1, 0), _C_FLEX, _C_EXT, 0.75, "neck"),
    DofRange("neck_lateral_flexion", False, (1, 0, 0), _C_LAT, _C_LAT, 0.8, "neck"),
    DofRange("neck_rotation", False, (0, 0, 1), _C_ROT, _C_ROT, 0.5, "neck"),
    DofRange("head_flexion", False, (0, 1, 0), _C_FLEX, _C_EXT, 0.25, "neck"),
    DofRange("head_lateral_flexion", False, (1, 0, 0), _C_LAT, _C_LAT, 0.2, "neck"),
    DofRange("head_rotation", False, (0, 0, 1), _C_ROT, _C_ROT, 0.5, "neck"),
    # clavicle (sterno-clavicular): lateral end up / forward.
    DofRange(
        "clavicle_elevation", True, (1, 0, 0),
        _m("elevation", NEUMANN=45), _m("depression", NEUMANN=10), group="shoulder",
    ),
    DofRange(
        "clavicle_protraction", True, (0, 0, -1),
        _m("protraction", NEUMANN=20), _m("retraction", NEUMANN=30), group="shoulder",
    ),
    # shoulder (gleno-humeral), chain flexion -> abduction -> rotation.
    DofRange(
        "shoulder_flexion", True, (0, -1, 0),
        _m("flexion", S1=180, S2=170, S3=130, S4=180),
        _m("hyperextension", S1=50, S2=30, S3=80, S4=60), group="shoulder",
    ),
    DofRange(
        "shoulder_abduction", True, (1, 0, 0),
        _m("abduction", S1=180, S2=170, S3=180, S4=180), _m("adduction", S1=50), group="shoulder",
    ),
    DofRange(
        "shoulder_rotation", True, (0, 0, -1),
        _m("internal rotation", S1=90, S2=90, S3=70, S4=90),
        _m("external rotation", S1=90, S2=90, S3=70, S4=90), group="shoulder",
    ),
    # elbow and forearm
    DofRange(
        "elbow_flexion", True, (0, -1, 0),
        _m("flexion", S1=140, S2=145, S3=145, S4=145),
        _m("hyperextension", False, S1=0, S2=0, S3=0, S4=10), group="arm",
    ),
    DofRange(
        "forearm_pronation", True, (0, 0, -1),
        _m("pronation", S1=80, S2=90, S3=90, S4=80),
        _m("supination", S1=80, S2=85, S3=90, S4=90), group="arm",
    ),
    # wrist: palm faces the thigh (-Y for the left hand), so palmar flexion is about -X.
    DofRange(
        "wrist_flexion", True, (-1, 0, 0),
        _m("flexion", S1=60, S2=90, S4=60), _m("extension", S1=60, S2=70, S3=70, S4=50), group="arm",
    ),
    DofRange(
        "wrist_deviation", True, (0, -1, 0),
        _m("radial deviation", S1=20, S2=20, S3=20, S4=20),
        _m("ulnar deviation", S1=30, S2=30, S3=35, S4=30), group="arm",
    ),
    # hip, chain flexion -> adduction -> rotation.
    DofRange(
        "hip_flexion", True, (0, -1, 0),
        _m("flexion", S1=100, S2=120, S3=125, S4=120),
        _m("hyperextension", S1=30, S2=10, S3=10, S4=30), group="leg",
    ),
    DofRange(
        "hip_adduction", True, (-1, 0, 0),
        _m("adduction", S1=20, S3=10, S4=25), _m("abduction", S1=40, S2=45, S3=45, S4=45), group="leg",
    ),
    DofRange(
        "hip_rotation", True, (0, 0, -1),
        _m("internal rotation", S1=40, S2=35, S3=45, S4=45),
        _m("external rotation", S1=50, S2=45, S3=45, S4=45), group="leg",
    ),
    DofRange(
        "knee_flexion", True, (0, 1, 0),
        _m("flexion", S1=150, S2=120, S3=140, S4=130),
        _m("hyperextension", False, S1=0, S2=0, S3=0, S4=0, AAOS=10), group="leg",
    ),
    DofRange(
        "ankle_dorsiflexion", True, (0, -1, 0),
        _m("dorsiflexion", S1=30, S2=15, S3=20, S4=20),
        _m("plantar flexion", S1=20, S2=45, S3=45, S4=50), group="leg",
    ),
    DofRange(
        "ankle_inversion", True, (-1, 0, 0),
        _m("inversion", AAOS=35), _m("eversion", AAOS=15), group="leg",
    ),
    DofRange(
        "toe_extension", True, (0, -1, 0),
        _m("extension", AAOS=70), _m("flexion", AAOS=45), group="leg",
    ),
)

_BY_STEM = {d.stem: d for d in ROM_TABLE}


def mirror_axis(axis) -> np.ndarray:
    """Axis of the mirrored joint: reflection through the XZ plane, ``(x, y, z) -> (-x, y, -z)``.

    A rotation ``R`` reflected by ``M = diag(1, -1, 1)`` is ``M R M``, whose
    axis is ``det(M) M a``; the angle keeps its sign and meaning.
    """
    a = np.asarray(axis, dtype=float)
    return np.array([-a[0], a[1], -a[2]]) + 0.0


def dof_names() -> tuple[str, ...]:
    """Every hinge name of the default humanoid, in table order, left before right."""
    out: list[str] = []
    for d in ROM_TABLE:
        out.extend([f"left_{d.stem}", f"right_{d.stem}"] if d.sided else [d.stem])
    return tuple(out)


def dof_entry(name: str) -> DofRange:
    """The table row of a (sided) hinge name; KeyError if the name is not in the table."""
    stem = name
    for side in ("left_", "right_"):
        if name.startswith(side):
            stem = name[len(side):]
            break
    d = _BY_STEM.get(stem)
    if d is None or d.sided != (stem != name):
        raise KeyError(f"no range-of-motion entry for joint {name!r}")
    return d


def joint_axis(name: str) -> np.ndarray:
    """Hinge axis of joint ``name`` of the default humanoid (body = world frame at rest)."""
    d = dof_entry(name)
    axis = np.asarray(d.axis, dtype=float)
    return mirror_axis(axis) if name.startswith("right_") else axis + 0.0


def joint_range_deg(name: str, policy: str = "default") -> tuple[float, float]:
    """``(lo, hi)`` degrees of joint ``name`` under ``policy`` (mirrored sides are equal)."""
    return dof_entry(name).range_deg(policy)


def joint_ranges_deg(policy: str = "default") -> dict[str, tuple[float, float]]:
    """``{joint name: (lo, hi)}`` degrees for every hinge of the default humanoid."""
    return {n: joint_range_deg(n, policy) for n in dof_names()}
