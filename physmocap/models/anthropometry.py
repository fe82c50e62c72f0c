"""Human body proportions, segment masses and radii of gyration, as data.

Everything here is a fraction: lengths of the stature ``H``, masses of the
total body mass ``M``, centre-of-mass positions and radii of gyration of the
segment length ``L``.  :mod:`physmocap.models.humanoid_builder` turns these
into the default humanoid ``assets/mjcf/humanoid.xml``.

Sources
-------
* **Lengths**: D. A. Winter, *Biomechanics and Motor Control of Human
  Movement*, 4th ed., Wiley 2009, Fig. 4.1 ("segment lengths expressed as a
  fraction of body height H", after Drillis and Contini, 1966).  Heights of
  the joint centres above the floor and the segment lengths are Winter's:

  ======================  =======  ==============================
  landmark / segment      x H      used as
  ======================  =======  ==============================
  top of head             1.000    ``head_end`` site, standing height
  chin                    0.870    ``head`` joint (C0/C1) height
  shoulder                0.818    ``neck`` (C7/T1), shoulder height
  hip (greater troch.)    0.530    hip joint centre height
  knee                    0.285    knee joint centre height
  ankle                   0.039    ankle joint centre height
  upper arm               0.186    shoulder to elbow
  forearm                 0.146    elbow to wrist
  hand                    0.108    wrist to finger tips
  thigh                   0.245    hip to knee  (0.530 - 0.285)
  shank                   0.246    knee to ankle (0.285 - 0.039)
  foot length             0.152    heel to toe tip
  foot width              0.055    foot box width
  shoulder width          0.259    between the shoulder joint centres
  hip width               0.191    pelvis geom breadth (bi-trochanteric)
  ======================  =======  ==============================

* **Trunk split**: Winter's figure gives the trunk only as a whole (hip to
  shoulder, 0.288 H).  It is split into lower, middle and upper trunk in the
  proportions of P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment
  inertia parameters", *J. Biomech.* 29(9):1223-1230, 1996, Table 4 (male:
  lower trunk 145.7 mm, middle trunk 215.5 mm, upper trunk 242.1 mm).  The
  ``spine`` joint sits at the top of the lower trunk (omphalion, ~L3/L4) and
  the ``chest`` joint at the top of the middle trunk (xiphion, ~T10-T12).

* **Hip joint spacing** is not in Winter's figure (0.191 H there is the hip
  *breadth*, used for the pelvis geom).  We use 0.11 H (19 cm at 1.75 m):
  Bell, Pedersen and Brand (*J. Biomech.* 23(6):617-621, 1990) place each hip
  joint centre 14 % of the inter-ASIS distance medial to its anterior superior
  iliac spine, which for an adult inter-ASIS distance of 23-26 cm gives
  17-19 cm between the hip joint centres; the real solved skeletons in
  ``../shared/data`` have 19.6 cm (OptiTrack Motive, metres) and about 22 cm
  (CMU).

* **Masses, centres of mass, radii of gyration**: Winter 2009, Table 4.1
  (Dempster's cadaver data via Miller and Nelson, and Plagenhoef): mass
  fraction of ``M``, centre of mass as a fraction of the segment length from
  the proximal end, radius of gyration about the centre of mass as a fraction
  of the segment length (for the transverse axes).  The trunk segments
  (Dempster's pelvis L4/L5-trochanter, abdomen T12/L1-L4/L5, thorax
  C7/T1-T12/L1) have mass fractions but no radii of gyration there; their
  inertias, the longitudinal inertias of the limbs and those of the head and
  neck are computed from the geoms as uniform solids of the segment's mass.

Modelling choices that are not in the sources are marked as such below.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "DEFAULT_HEIGHT",
    "DEFAULT_MASS",
    "LENGTH_FRACTIONS",
    "TRUNK_SPLIT_DE_LEVA",
    "SEGMENT_MASS",
    "SegmentInertia",
    "Proportions",
    "proportions",
]

#: Stature of the default humanoid, metres.
DEFAULT_HEIGHT = 1.75
#: Body mass of the default humanoid, kg (a 1.75 m adult with BMI 22.9).
DEFAULT_MASS = 70.0

#: Winter (2009) Fig. 4.1, fractions of stature H (see module docstring).
LENGTH_FRACTIONS: dict[str, float] = {
    "head_top": 1.000,
    "chin": 0.870,
    "shoulder": 0.818,
    "hip": 0.530,
    "knee": 0.285,
    "ankle": 0.039,
    "upper_arm": 0.186,
    "forearm": 0.146,
    "hand": 0.108,
    "thigh": 0.245,
    "shank": 0.246,
    "foot_length": 0.152,
    "foot_width": 0.055,
    "shoulder_width": 0.259,
    "hip_breadth": 0.191,
    # Not in Winter's figure (see module docstring): hip joint centre spacing.
    "hip_spacing": 0.110,
}

#: de Leva (1996) Table 4, male trunk sub-segment lengths (mm): lower, middle, upper.
TRUNK_SPLIT_DE_LEVA: tuple[float, float, float] = (145.7, 215.5, 242.1)


@dataclass(frozen=True)
class SegmentInertia:
    """Winter (2009) Table 4.1 row.

    Attributes:
        mass: segment mass / total body mass.
        com: centre of mass distance from the proximal joint / segment length.
        gyration: radius of gyration about the centre of mass / segment length
            (transverse axes), or ``None`` when the table gives none.
    """

    mass: float
    com: float
    gyration: float | None


#: Winter (2009) Table 4.1 (Dempster).  Masses sum to 1.000.
SEGMENT_MASS: dict[str, SegmentInertia] = {
    "hand": SegmentInertia(0.006, 0.506, 0.297),
    "forearm": SegmentInertia(0.016, 0.430, 0.303),
    "upper_arm": SegmentInertia(0.028, 0.436, 0.322),
    "foot": SegmentInertia(0.0145, 0.50, 0.475),
    "shank": SegmentInertia(0.0465, 0.433, 0.302),
    "thigh": SegmentInertia(0.100, 0.433, 0.323),
    "head_neck": SegmentInertia(0.081, 1.000, 0.495),
    # Dempster's trunk split, Winter Table 4.1: thorax 0.216, abdomen 0.139, pelvis 0.142.
    "thorax": SegmentInertia(0.216, 0.82, None),
    "abdomen": SegmentInertia(0.139, 0.44, None),
    "pelvis": SegmentInertia(0.142, 0.105, None),
}

#: Modelling choices (not in the sources): share of a Winter segment's mass
#: given to a sub-body the table does not have.
CLAVICLE_SHARE_OF_THORAX = 0.05  # each clavicle body takes 5 % of the thorax mass (shoulder girdle)
NECK_SHARE_OF_HEAD_NECK = 0.20  # neck body 20 %, head 80 % of Winter's head-and-neck mass
TOES_SHARE_OF_FOOT = 0.20  # toes body 20 %, rear- and mid-foot 80 % of the foot mass


@dataclass(frozen=True)
class Proportions:
    """Joint-centre layout of a human of stature ``height`` (metres, Z-up, facing +X).

    Heights are above the floor; lateral offsets are positive to the left (+Y).
    """

    height: float
    mass: float
    hip_z: float
    spine_z: float
    chest_z: float
    neck_z: float
    head_z: float
    shoulder_z: float
    hip_y: float
    shoulder_y: float
    clavicle_y: float
    clavicle_z: float
    knee_z: float
    ankle_z: float
    upper_arm: float
    forearm: float
    hand: float
    foot_length: float
    foot_width: float
    hip_breadth: float
    heel_x: float
    ball_x: float
    toe_x: float

    def segment(self, name: str) -> float:
        """Length in metres of a Winter segment named in :data:`LENGTH_FRACTIONS`."""
        return LENGTH_FRACTIONS[name] * self.height


#: Modelling choices for the foot (not in Winter's figure), fractions of foot
#: length measured from the heel: the ankle joint centre lies above 0.25 of the
#: foot length, the ball (first metatarsophalangeal joint) at 0.73.
ANKLE_FROM_HEEL = 0.25
BALL_FROM_HEEL = 0.73

#: Modelling choice: sterno-clavicular joints 2 cm either side of the midline
#: (as a fraction of H) and 3 cm below the shoulder line.
CLAVICLE_Y = 0.0115
CLAVICLE_DROP = 0.017


def proportions(height: float = DEFAULT_HEIGHT, mass: float = DEFAULT_MASS) -> Proportions:
    """Joint-centre layout of the default humanoid scaled to ``height`` (m) and ``mass`` (kg)."""
    H = float(height)
    f = LENGTH_FRACTIONS
    hip_z = f["hip"] * H
    neck_z = f["shoulder"] * H
    trunk = neck_z - hip_z
    lower, middle, upper = TRUNK_SPLIT_DE_LEVA
    total = lower + middle + upper
    spine_z = hip_z + trunk * lower / total
    chest_z = spine_z + trunk * middle / total
    foot = f["foot_length"] * H
    return Proportions(
        height=H,
        mass=float(mass),
        hip_z=hip_z,
        spine_z=spine_z,
        chest_z=chest_z,
        neck_z=neck_z,
        head_z=f["chin"] * H,
        shoulder_z=f["shoulder"] * H,
        hip_y=f["hip_spacing"] * H / 2.0,
        shoulder_y=f["shoulder_width"] * H / 2.0,
        clavicle_y=CLAVICLE_Y * H,
        clavicle_z=(f["shoulder"] - CLAVICLE_DROP) * H,
        knee_z=f["knee"] * H,
        ankle_z=f["ankle"] * H,
        upper_arm=f["upper_arm"] * H,
        forearm=f["forearm"] * H,
        hand=f["hand"] * H,
        foot_length=foot,
        foot_width=f["foot_width"] * H,
        hip_breadth=f["hip_breadth"] * H,
        heel_x=-ANKLE_FROM_HEEL * foot,
        ball_x=(BALL_FROM_HEEL - ANKLE_FROM_HEEL) * foot,
        toe_x=(1.0 - ANKLE_FROM_HEEL) * foot,
    )
