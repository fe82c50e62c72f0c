"""Generate the default humanoid MJCF from the anthropometric and range-of-motion tables.

``python scripts/generate_humanoid.py`` writes ``assets/mjcf/humanoid.xml``
with :func:`humanoid_xml`; a test regenerates it and compares bytes, so the
committed file and the tables never drift apart.

Layout (rest pose = anatomical neutral, every body frame aligned with the
world: X forward, Y left, Z up; the character faces +X):

* ``pelvis`` (free joint ``root``) at the mid-point of the hip joint centres.
* ``lumbar`` (``spine`` joint, 3 hinges), ``thorax`` (``chest``, 3 hinges),
  ``neck`` (3 hinges), ``head`` (3 hinges).
* ``<side>_clavicle`` (sterno-clavicular, 2 hinges), ``<side>_upper_arm``
  (shoulder, 3 hinges), ``<side>_forearm`` (elbow flexion and forearm
  pronation), ``<side>_hand`` (wrist, 2 hinges).
* ``<side>_thigh`` (hip, 3 hinges), ``<side>_shank`` (knee, 1 hinge),
  ``<side>_foot`` (ankle: dorsiflexion and inversion), ``<side>_toes``
  (metatarsophalangeal extension).

Each body carries a site named after the canonical joint that *moves* it, at
that joint's centre, and end sites ``head_end``, ``<side>_hand_end`` and
``<side>_toe_end``.  Each foot has contact sites ``<side>_heel``,
``<side>_ball`` and ``<side>_toe_tip`` on the sole (z = 0 at rest), each under
a small collision capsule across the foot.

Masses: Winter's mass fractions; inertias: Winter's radii of gyration for the
limbs' transverse axes, uniform solids of the geoms otherwise
(:mod:`physmocap.models.anthropometry`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .anthropometry import (
    CLAVICLE_SHARE_OF_THORAX,
    DEFAULT_HEIGHT,
    DEFAULT_MASS,
    NECK_SHARE_OF_HEAD_NECK,
    SEGMENT_MASS,
    TOES_SHARE_OF_FOOT,
    Proportions,
    proportions,
)
from .rom import ROM_TABLE, joint_axis, joint_range_deg

__all__ = ["humanoid_xml", "scene_xml", "SIDES"]

SIDES = ("left", "right")

#: Modelling choices for geom radii and the foot, as fractions of stature H.
_R = {
    "pelvis": 0.050,
    "waist": 0.046,
    "chest": 0.058,
    "neck": 0.028,
    "head": 0.0575,
    "clavicle": 0.011,
    "upper_arm": 0.022,
    "forearm": 0.018,
    "thigh": 0.038,
    "shank": 0.029,
    "contact": 0.009,  # foot contact capsules
    "toe_joint": 0.013,  # height of the MTP joint centre above the sole
}


# -- number formatting: fixed precision so the file is byte-stable --------------
def _f(x: float) -> str:
    s = f"{float(x):.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _v(*xs: float) -> str:
    return " ".join(_f(x) for x in xs)


# -- inertia of uniform solids (about the centre of mass, axis-aligned) ------------
def _capsule_inertia(mass: float, radius: float, length: float, axis: int) -> np.ndarray:
    """Diagonal inertia of a solid capsule, cylinder length ``length`` along ``axis``."""
    r, h = radius, length
    v_cyl = math.pi * r * r * h
    v_sph = 4.0 / 3.0 * math.pi * r**3
    rho = mass / (v_cyl + v_sph)
    mc, ms = rho * v_cyl, rho * v_sph
    i_axial = mc * r * r / 2.0 + ms * 2.0 * r * r / 5.0
    i_trans = mc * (h * h / 12.0 + r * r / 4.0) + ms * (2.0 * r * r / 5.0 + h * h / 4.0 + 3.0 * h * r / 8.0)
    out = np.full(3, i_trans)
    out[axis] = i_axial
    return out


def _box_inertia(mass: float, half: tuple[float, float, float]) -> np.ndarray:
    a, b, c = (2.0 * x for x in half)
    return mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])


def _limb_inertia(mass: float, length: float, gyration: float, radius: float) -> np.ndarray:
    """Limb along Z: Winter's radius of gyration for X and Y, a solid cylinder about Z."""
    i_t = mass * (gyration * length) ** 2
    return np.array([i_t, i_t, mass * radius * radius / 2.0])


@dataclass
class _Body:
    el: ET.Element
    name: str
    hinges: list[str] = field(default_factory=list)


class _Builder:
    def __init__(self, p: Proportions) -> None:
        self.p = p
        self.H = p.height
        self.hinges: list[str] = []

    def r(self, key: str) -> float:
        return _R[key] * self.H

    # elements --------------------------------------------------------------
    def body(self, parent: ET.Element, name: str, pos, childclass: str | None = None) -> ET.Element:
        attrs = {"name": name, "pos": _v(*pos)}
        if childclass:
            attrs["childclass"] = childclass
        return ET.SubElement(parent, "body", attrs)

    def inertial(self, body: ET.Element, pos, mass: float, diag) -> None:
        ET.SubElement(
            body, "inertial", {"pos": _v(*pos), "mass": _f(mass), "diaginertia": _v(*diag)}
        )

    def hinge(self, body: ET.Element, name: str, group: str) -> None:
        lo, hi = joint_range_deg(name)
        ET.SubElement(
            body,
            "joint",
            {
                "name": name,
                "class": group,
                "axis": _v(*joint_axis(name)),
                "range": _v(lo, hi),
            },
        )
        self.hinges.append(name)

    def hinges_of(self, body: ET.Element, prefix: str, stems: list[str]) -> None:
        for stem in stems:
            entry = next(d for d in ROM_TABLE if d.stem == stem)
            self.hinge(body, f"{prefix}{stem}", entry.group)

    def site(self, body: ET.Element, name: str, pos=(0, 0, 0), cls: str = "joint_site") -> None:
        ET.SubElement(body, "site", {"name": name, "class": cls, "pos": _v(*pos)})

    def capsule(self, body: ET.Element, name: str, a, b, radius: float, cls: str = "body") -> None:
        ET.SubElement(
            body,
            "geom",
            {"name": name, "class": cls, "type": "capsule", "fromto": _v(*a, *b), "size": _f(radius)},
        )

    def sphere(self, body: ET.Element, name: str, pos, radius: float, cls: str = "body") -> None:
        ET.SubElement(
            body, "geom", {"name": name, "class": cls, "type": "sphere", "pos": _v(*pos), "size": _f(radius)}
        )

    def box(self, body: ET.Element, name: str, pos, half, cls: str = "body") -> None:
        ET.SubElement(
            body, "geom", {"name": name, "class": cls, "type": "box", "pos": _v(*pos), "size": _v(*half)}
        )

    # the model ------------------------------------------------------------------
    def build(self, worldbody: ET.Element) -> None:
        p, M = self.p, self.p.mass
        # pelvis: capsule across the hips, Dempster's pelvis mass.
        pelvis = self.body(worldbody, "pelvis", (0, 0, p.hip_z), "humanoid")
        ET.SubElement(pelvis, "freejoint", {"name": "root"})
        self.site(pelvis, "pelvis")
        rp = self.r("pelvis")
        half = p.hip_breadth / 2.0 - rp
        pz = 0.35 * (p.spine_z - p.hip_z)
        self.capsule(pelvis, "pelvis", (0, -half, pz), (0, half, pz), rp)
        m = SEGMENT_MASS["pelvis"].mass * M
        self.inertial(pelvis, (0, 0, pz), m, _capsule_inertia(m, rp, 2 * half, 1))

        # lumbar (abdomen)
        lumbar = self.body(pelvis, "lumbar", (0, 0, p.spine_z - p.hip_z))
        self.hinges_of(lumbar, "", ["lumbar_flexion", "lumbar_lateral_flexion", "lumbar_rotation"])
        self.site(lumbar, "spine")
        rw = self.r("waist")
        wz = 0.5 * (p.chest_z - p.spine_z)
        half = 0.035 * self.H
        self.capsule(lumbar, "waist", (0, -half, wz), (0, half, wz), rw)
        m = SEGMENT_MASS["abdomen"].mass * M
        self.inertial(lumbar, (0, 0, wz), m, _capsule_inertia(m, rw, 2 * half, 1))

        # thorax
        thorax = self.body(lumbar, "thorax", (0, 0, p.chest_z - p.spine_z))
        self.hinges_of(thorax, "", ["thoracic_flexion", "thoracic_lateral_flexion", "thoracic_rotation"])
        self.site(thorax, "chest")
        rc = self.r("chest")
        cz = 0.5 * (p.neck_z - p.chest_z)
        half = 0.045 * self.H
        self.capsule(thorax, "chest", (0, -half, cz), (0, half, cz), rc)
        m = SEGMENT_MASS["thorax"].mass * M * (1.0 - 2.0 * CLAVICLE_SHARE_OF_THORAX)
        self.inertial(thorax, (0, 0, cz), m, _capsule_inertia(m, rc, 2 * half, 1))

        # neck and head
        neck = self.body(thorax, "neck", (0, 0, p.neck_z - p.chest_z))
        self.hinges_of(neck, "", ["neck_flexion", "neck_lateral_flexion", "neck_rotation"])
        self.site(neck, "neck")
        rn = self.r("neck")
        nl = p.head_z - p.neck_z
        self.capsule(neck, "neck", (0, 0, 0), (0, 0, nl), rn)
        m_hn = SEGMENT_MASS["head_neck"].mass * M
        m = m_hn * NECK_SHARE_OF_HEAD_NECK
        self.inertial(neck, (0, 0, nl / 2), m, _capsule_inertia(m, rn, nl, 2))

        head = self.body(neck, "head", (0, 0, p.head_z - p.neck_z))
        self.hinges_of(head, "", ["head_flexion", "head_lateral_flexion", "head_rotation"])
        self.site(head, "head")
        top = self.H - p.head_z
        self.site(head, "head_end", (0, 0, top))
        rh = self.r("head")
        hc = (0.01 * self.H, 0, top - rh)
        self.sphere(head, "head", hc, rh)
        m = m_hn * (1.0 - NECK_SHARE_OF_HEAD_NECK)
        self.inertial(head, hc, m, np.full(3, 0.4 * m * rh * rh))

        for side in SIDES:
            self.arm(thorax, side)
        for side in SIDES:
            self.leg(pelvis, side)

    def arm(self, thorax: ET.Element, side: str) -> None:
        p, M, s = self.p, self.p.mass, (1.0 if side == "left" else -1.0)
        pre = f"{side}_"
        clav = self.body(
            thorax, f"{pre}clavicle", (0, s * p.clavicle_y, p.clavicle_z - p.chest_z)
        )
        self.hinges_of(clav, pre, ["clavicle_elevation", "clavicle_protraction"])
        self.site(clav, f"{pre}clavicle")
        d = (0, s * (p.shoulder_y - p.clavicle_y), p.shoulder_z - p.clavicle_z)
        rcl = self.r("clavicle")
        self.capsule(clav, f"{pre}clavicle", (0, 0, 0), d, rcl)
        m = SEGMENT_MASS["thorax"].mass * M * CLAVICLE_SHARE_OF_THORAX
        length = float(np.linalg.norm(d))
        self.inertial(clav, np.array(d) / 2, m, _capsule_inertia(m, rcl, length, 1))

        upper = self.body(clav, f"{pre}upper_arm", d)
        self.hinges_of(upper, pre, ["shoulder_flexion", "shoulder_abduction", "shoulder_rotation"])
        self.site(upper, f"{pre}shoulder")
        self.limb(upper, f"{pre}upper_arm", p.upper_arm, self.r("upper_arm"), "upper_arm")

        fore = self.body(upper, f"{pre}forearm", (0, 0, -p.upper_arm))
        self.hinges_of(fore, pre, ["elbow_flexion", "forearm_pronation"])
        self.site(fore, f"{pre}elbow")
        self.limb(fore, f"{pre}forearm", p.forearm, self.r("forearm"), "forearm")

        hand = self.body(fore, f"{pre}hand", (0, 0, -p.forearm))
        self.hinges_of(hand, pre, ["wrist_flexion", "wrist_deviation"])
        self.site(hand, f"{pre}wrist")
        self.site(hand, f"{pre}hand_end", (0, 0, -p.hand))
        # palm faces the thigh: the hand is broad along X, thin along Y.
        half = (0.024 * self.H, 0.008 * self.H, p.hand / 2.0)
        self.box(hand, f"{pre}hand", (0, 0, -p.hand / 2.0), half)
        seg = SEGMENT_MASS["hand"]
        m = seg.mass * M
        i_t = m * (seg.gyration * p.hand) ** 2
        box = _box_inertia(m, half)
        self.inertial(hand, (0, 0, -seg.com * p.hand), m, (i_t, i_t, box[2]))

    def limb(self, body: ET.Element, name: str, length: float, radius: float, seg_key: str) -> None:
        self.capsule(body, name, (0, 0, 0), (0, 0, -length), radius)
        seg = SEGMENT_MASS[seg_key]
        m = seg.mass * self.p.mass
        assert seg.gyration is not None
        self.inertial(body, (0, 0, -seg.com * length), m, _limb_inertia(m, length, seg.gyration, radius))

    def leg(self, pelvis: ET.Element, side: str) -> None:
        p, M, s = self.p, self.p.mass, (1.0 if side == "left" else -1.0)
        pre = f"{side}_"
        thigh = self.body(pelvis, f"{pre}thigh", (0, s * p.hip_y, 0))
        self.hinges_of(thigh, pre, ["hip_flexion", "hip_adduction", "hip_rotation"])
        self.site(thigh, f"{pre}hip")
        lt = p.hip_z - p.knee_z
        self.limb(thigh, f"{pre}thigh", lt, self.r("thigh"), "thigh")

        shank = self.body(thigh, f"{pre}shank", (0, 0, -lt))
        self.hinges_of(shank, pre, ["knee_flexion"])
        self.site(shank, f"{pre}knee")
        ls = p.knee_z - p.ankle_z
        self.limb(shank, f"{pre}shank", ls, self.r("shank"), "shank")

        foot = self.body(shank, f"{pre}foot", (0, 0, -ls))
        self.hinges_of(foot, pre, ["ankle_dorsiflexion", "ankle_inversion"])
        self.site(foot, f"{pre}ankle")
        sole = -p.ankle_z
        rc = self.r("contact")
        hw = p.foot_width / 2.0
        # rear- and mid-foot: contact capsules across the heel and the ball, and a visual
        # box between their axes whose underside is at the capsules' axes, so the
        # capsules (and the contact sites under them) are always the lowest points of
        # the foot, however it pitches or rolls.
        fx0, fx1 = p.heel_x, p.ball_x
        fz1 = 0.6 * p.ankle_z
        heel_x = fx0 + rc
        half = ((fx1 - heel_x) / 2.0, hw, (fz1 - (sole + rc)) / 2.0)
        centre = ((heel_x + fx1) / 2.0, 0, (fz1 + sole + rc) / 2.0)
        self.box(foot, f"{pre}foot", centre, half, cls="visual")
        self.capsule(foot, f"{pre}heel", (heel_x, -hw + rc, sole + rc), (heel_x, hw - rc, sole + rc), rc, "foot_contact")
        self.capsule(foot, f"{pre}ball", (fx1, -hw + rc, sole + rc), (fx1, hw - rc, sole + rc), rc, "foot_contact")
        self.site(foot, f"{pre}heel", (heel_x, 0, sole), "contact_site")
        self.site(foot, f"{pre}ball", (fx1, 0, sole), "contact_site")
        seg = SEGMENT_MASS["foot"]
        m = seg.mass * M * (1.0 - TOES_SHARE_OF_FOOT)
        box = _box_inertia(m, half)
        i_t = m * (seg.gyration * (fx1 - fx0)) ** 2
        self.inertial(foot, centre, m, (box[0], i_t, i_t))

        # toes: hinge at the ball (MTP joint), toe tip at the front of the foot.
        tj = self.r("toe_joint")
        toes = self.body(foot, f"{pre}toes", (fx1, 0, sole + tj))
        self.hinges_of(toes, pre, ["toe_extension"])
        self.site(toes, f"{pre}toe")
        tl = p.toe_x - p.ball_x
        self.site(toes, f"{pre}toe_end", (tl, 0, 0))
        tip_x = tl - rc
        th = (tip_x / 2.0, hw, (1.5 * tj - rc) / 2.0)
        tc = (tip_x / 2.0, 0, -tj + rc + th[2])
        self.box(toes, f"{pre}toes", tc, th, cls="visual")
        self.capsule(toes, f"{pre}toe_tip", (tip_x, -hw + rc, -tj + rc), (tip_x, hw - rc, -tj + rc), rc, "foot_contact")
        self.site(toes, f"{pre}toe_tip", (tip_x, 0, -tj), "contact_site")
        m = seg.mass * M * TOES_SHARE_OF_FOOT
        self.inertial(toes, tc, m, _box_inertia(m, th))


_DEFAULTS = """
<default>
  <default class="humanoid">
    <joint type="hinge" limited="true" armature="0.01" damping="1" frictionloss="0"/>
    <geom contype="0" conaffinity="1" condim="3" friction="1 0.005 0.0001" group="1" rgba="0.8 0.6 0.45 1"/>
    <site group="4" size="0.012" rgba="0.2 0.4 1 1"/>
    <default class="spine"><joint damping="5" armature="0.05"/></default>
    <default class="neck"><joint damping="1" armature="0.02"/></default>
    <default class="shoulder"><joint damping="2" armature="0.02"/></default>
    <default class="arm"><joint damping="0.5" armature="0.01"/></default>
    <default class="leg"><joint damping="2" armature="0.02"/></default>
    <default class="body"/>
    <default class="visual"><geom contype="0" conaffinity="0" group="2"/></default>
    <default class="foot_contact">
      <geom type="capsule" condim="3" priority="1" friction="1 0.02 0.001" group="3" rgba="0.9 0.3 0.2 1"/>
    </default>
    <default class="joint_site"><site type="sphere"/></default>
    <default class="contact_site"><site type="sphere" size="0.008" rgba="1 0.2 0.2 1"/></default>
  </default>
</default>
"""

_HEADER = """Default physmocap humanoid, GENERATED by scripts/generate_humanoid.py from
physmocap/models/anthropometry.py (Winter 2009 segment lengths and masses) and
physmocap/models/rom.py (goniometry ranges, "default" policy). Do not edit by hand.

Stature {H} m, mass {M} kg. World Z-up, floor at z=0, facing +X, left is +Y.
Rest pose (qpos0 and keyframe "rest"): anatomical neutral, palms facing the thighs,
every hinge at 0 and every body frame aligned with the world. Angles in degrees.
Collision: body geoms have contype=0 conaffinity=1, so they collide with the
floor (contype=1) and other scene objects but never with each other."""


def humanoid_xml(height: float = DEFAULT_HEIGHT, mass: float = DEFAULT_MASS) -> str:
    """MJCF text of the default humanoid of stature ``height`` m and mass ``mass`` kg."""
    p = proportions(height, mass)
    root = ET.Element("mujoco", {"model": "humanoid"})
    root.append(ET.Comment(" " + _HEADER.format(H=_f(p.height), M=_f(p.mass)) + " "))
    ET.SubElement(root, "compiler", {"angle": "degree", "autolimits": "true", "inertiafromgeom": "false"})
    root.append(ET.fromstring(_DEFAULTS))
    world = ET.SubElement(root, "worldbody")
    b = _Builder(p)
    b.build(world)
    keyframe = ET.SubElement(root, "keyframe")
    qpos = [0.0, 0.0, p.hip_z, 1.0, 0.0, 0.0, 0.0] + [0.0] * len(b.hinges)
    ET.SubElement(keyframe, "key", {"name": "rest", "qpos": _v(*qpos)})
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def scene_xml(model_file: str = "humanoid.xml", name: str = "humanoid scene") -> str:
    """MJCF text of a scene: floor plane at z = 0, light, sky; includes ``model_file``."""
    return f"""<mujoco model="{name}">
  <include file="{model_file}"/>

  <statistic center="0 0 0.9" extent="2"/>

  <visual>
    <headlight diffuse="0.6 0.6 0.6" ambient="0.3 0.3 0.3" specular="0 0 0"/>
    <global azimuth="160" elevation="-20"/>
  </visual>

  <asset>
    <texture type="skybox" builtin="gradient" rgb1="0.3 0.5 0.7" rgb2="0 0 0" width="512" height="3072"/>
    <texture type="2d" name="groundplane" builtin="checker" mark="edge" rgb1="0.2 0.3 0.4"
      rgb2="0.1 0.2 0.3" markrgb="0.8 0.8 0.8" width="300" height="300"/>
    <material name="groundplane" texture="groundplane" texuniform="true" texrepeat="5 5" reflectance="0.2"/>
  </asset>

  <worldbody>
    <light pos="0 0 3.5" dir="0 0 -1" directional="true"/>
    <geom name="floor" size="0 0 0.05" type="plane" material="groundplane" contype="1" conaffinity="1"/>
  </worldbody>
</mujoco>
"""


def mapping_toml() -> str:
    """Mapping file of the default humanoid: every canonical joint is the site of the same name."""
    from ..canonical import CANONICAL_NAMES

    width = max(len(n) for n in CANONICAL_NAMES)
    joints = "\n".join(f'{n.ljust(width)} = "site:{n}"' for n in CANONICAL_NAMES)
    return f"""# Mapping of the default humanoid (GENERATED by scripts/generate_humanoid.py).
# Canonical joints (physmocap/canonical.py) -> sites of assets/mjcf/humanoid.xml.

[character]
name = "humanoid"
up = "Z"
forward = "X"
require_limits = true
range_policy = "default"   # or "strict": clinical medians (physmocap/models/rom.py)

[joints]
{joints}

[contacts]
left = ["left_heel", "left_ball", "left_toe_tip"]
right = ["right_heel", "right_ball", "right_toe_tip"]

[rest]
keyframe = "rest"

# Velocity limits come from physmocap/models/velocity.py; override here in deg/s, e.g.
# [velocity_limits]
# left_knee_flexion = 2500
"""
