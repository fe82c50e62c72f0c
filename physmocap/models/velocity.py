"""Peak joint angular velocities of the default humanoid, as data.

The retargeter bounds each hinge's speed by these limits.  They are the peak
values reported for fast, skilled human movements (sprinting, jumping,
kicking, throwing), so real capture of walking, jumping and crouching stays far
below them; only capture glitches (a joint flipping between two frames) hit
them.  Figures are in degrees per second and rounded up; the order of
magnitude is what matters.

Sources
-------
* ``FLEISIG95``: G. S. Fleisig et al., "Kinetics of baseball pitching with
  implications about injury mechanisms", *Am. J. Sports Med.* 23(2), 1995:
  shoulder internal rotation ~7000 deg/s, elbow extension ~2300 deg/s, upper
  trunk rotation ~1200 deg/s, pelvis rotation ~650 deg/s.
* ``NUNOME02``: H. Nunome et al., "Three-dimensional kinetic analysis of side-foot
  and instep soccer kicks", *Med. Sci. Sports Exerc.* 34(12), 2002: knee
  extension up to ~2000 deg/s, hip flexion ~800-1000 deg/s in the kick.
* ``BOBBERT88``: M. F. Bobbert and G. J. van Ingen Schenau, "Coordination in
  vertical jumping", *J. Biomech.* 21(3), 1988: ankle plantar flexion
  ~1000 deg/s, knee ~1000 deg/s, hip ~700 deg/s at take-off.
* ``ELLIOTT95``: B. Elliott et al., "Contribution of upper limb segment
  rotations during the power serve in tennis", *J. Appl. Biomech.* 11, 1995:
  wrist flexion ~1900 deg/s, forearm pronation ~1400 deg/s.
* ``NOVACHECK98``: T. F. Novacheck, "The biomechanics of running", *Gait &
  Posture* 7, 1998: sagittal hip and knee ~800-1200 deg/s in sprinting; the
  metatarsophalangeal joint ~800 deg/s at toe-off.
* ``ESTIMATE``: no peak found in the literature; set generously by analogy
  with the neighbouring joints (spine bending, neck, clavicle, ankle inversion,
  hip ab/adduction and rotation, wrist deviation).
* ``CAPTURE``: raised above the literature value because the real recordings
  in ``../shared/data`` exceed it: the toes (metatarsophalangeal joint, ~800
  deg/s in NOVACHECK98) reach 1000-1300 deg/s at the 99.5th percentile of the
  CMU and PyMO walks at toe-off.

Check: ``scripts/joint_speeds.py`` prints, for every joint of the shared BVH
recordings, the median, 99.9th percentile and maximum local rotation speed next
to the smallest limit of the hinges that joint drives; ``tests/test_character_velocity.py``
asserts that the 99th percentile stays below it.  What exceeds the limits there
are single-frame glitches (frame 0 of the CMU files, whole-skeleton jumps in
the OptiTrack take), which the limits are meant to clip.

A mapping file can override any of these (``[velocity_limits]``), and a
character whose joints are not in this table gets the mapping file's
``default`` or :data:`FALLBACK_DEG_S`.
"""

from __future__ import annotations

import math

from .rom import dof_entry

__all__ = ["PEAK_VELOCITY_DEG_S", "FALLBACK_DEG_S", "human_velocity_limit"]

#: Peak angular speed per hinge stem, deg/s, and its source.
PEAK_VELOCITY_DEG_S: dict[str, tuple[float, str]] = {
    "lumbar_flexion": (600.0, "ESTIMATE"),
    "lumbar_lateral_flexion": (500.0, "ESTIMATE"),
    "lumbar_rotation": (700.0, "FLEISIG95"),
    "thoracic_flexion": (600.0, "ESTIMATE"),
    "thoracic_lateral_flexion": (500.0, "ESTIMATE"),
    "thoracic_rotation": (1200.0, "FLEISIG95"),
    "neck_flexion": (800.0, "ESTIMATE"),
    "neck_lateral_flexion": (800.0, "ESTIMATE"),
    "neck_rotation": (800.0, "ESTIMATE"),
    "head_flexion": (800.0, "ESTIMATE"),
    "head_lateral_flexion": (800.0, "ESTIMATE"),
    "head_rotation": (800.0, "ESTIMATE"),
    "clavicle_elevation": (600.0, "ESTIMATE"),
    "clavicle_protraction": (600.0, "ESTIMATE"),
    "shoulder_flexion": (1500.0, "FLEISIG95"),
    "shoulder_abduction": (1500.0, "FLEISIG95"),
    "shoulder_rotation": (7000.0, "FLEISIG95"),
    "elbow_flexion": (2400.0, "FLEISIG95"),
    "forearm_pronation": (1500.0, "ELLIOTT95"),
    "wrist_flexion": (2000.0, "ELLIOTT95"),
    "wrist_deviation": (1000.0, "ESTIMATE"),
    "hip_flexion": (1200.0, "NOVACHECK98"),
    "hip_adduction": (800.0, "ESTIMATE"),
    "hip_rotation": (800.0, "ESTIMATE"),
    "knee_flexion": (2000.0, "NUNOME02"),
    "ankle_dorsiflexion": (1200.0, "BOBBERT88"),
    "ankle_inversion": (1000.0, "ESTIMATE"),
    "toe_extension": (1500.0, "CAPTURE"),
}

#: Speed limit for hinges no table or mapping file names, deg/s.
FALLBACK_DEG_S = 1000.0


def human_velocity_limit(name: str) -> float | None:
    """Velocity limit in rad/s of a default-humanoid hinge, or None if not in the table."""
    try:
        stem = dof_entry(name).stem
    except KeyError:
        return None
    return math.radians(PEAK_VELOCITY_DEG_S[stem][0])
