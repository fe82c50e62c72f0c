"""The humanoid's velocity limits do not clip real capture (walks, jumps, hops and crouches)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from physmocap.models import load_character
from physmocap.models.velocity import PEAK_VELOCITY_DEG_S, human_velocity_limit
from conftest import SHARED_BVH, shared_file

#: BVH joint name pattern -> humanoid hinge stems driven by that joint (first match wins).
GROUPS = [
    (r"upleg", ["hip_flexion", "hip_adduction", "hip_rotation"]),
    (r"toe", ["toe_extension"]),
    (r"foot", ["ankle_dorsiflexion", "ankle_inversion"]),
    (r"leg", ["knee_flexion"]),
    (r"forearm", ["elbow_flexion", "forearm_pronation"]),
    (r"hand$", ["wrist_flexion", "wrist_deviation"]),
    (r"shoulder", ["clavicle_elevation", "clavicle_protraction"]),
    (r"arm$", ["shoulder_flexion", "shoulder_abduction", "shoulder_rotation"]),
    (r"neck", ["neck_flexion", "neck_lateral_flexion", "neck_rotation"]),
    (r"^head$", ["head_flexion", "head_lateral_flexion", "head_rotation"]),
    (r"spine|lowerback", ["lumbar_flexion", "lumbar_lateral_flexion", "lumbar_rotation"]),
]


def test_limits_cover_every_humanoid_hinge():
    ch = load_character()
    for name, v in ch.velocity_limits.items():
        assert v == pytest.approx(human_velocity_limit(name))
    assert set(PEAK_VELOCITY_DEG_S) == {n.removeprefix("left_") for n in ch.velocity_limits if not n.startswith("right_")}


@pytest.mark.parametrize("name", SHARED_BVH)
def test_real_capture_is_not_clipped(name):
    from physmocap.sources import load_motion

    motion = load_motion(shared_file(name))
    q = motion.rotations
    dots = np.abs(np.sum(q[1:] * q[:-1], axis=-1)).clip(0.0, 1.0)
    speed = np.degrees(2.0 * np.arccos(dots)) * motion.fps  # local rotation speed, deg/s
    checked = 0
    for j, joint in enumerate(motion.skeleton.names):
        stems = next((s for pat, s in GROUPS if re.search(pat, joint.lower())), None)
        if stems is None or motion.skeleton.end_site[j]:
            continue
        limit = min(PEAK_VELOCITY_DEG_S[s][0] for s in stems)
        p99 = float(np.percentile(speed[:, j], 99))
        assert p99 < limit, f"{name}: {joint} turns at {p99:.0f} deg/s (99th percentile), limit {limit:.0f}"
        checked += 1
    assert checked >= 14
