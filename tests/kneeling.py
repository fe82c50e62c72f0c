"""A synthetic actor who goes down on all fours: knees and hands on the floor.

Positions of the canonical joints (metres, Z-up, facing +X) built from a few
sagittal angles, so every segment keeps its length: the actor stands for
``stand`` seconds, kneels down over ``down`` seconds (shanks rotating back
about the ankles until they lie on the floor, the trunk pitching forward, the
arms hanging) and holds the all-fours pose with a slight sway for ``hold``
seconds.  In the held pose the knee joint centres are ``knee_height`` above
the floor and the wrists ``wrist_height`` (palms flat, finger tips at 1 cm).
"""

from __future__ import annotations

import numpy as np

from physmocap.motion import Motion, Skeleton

THIGH, SHANK, TRUNK, NECK, HEAD = 0.42, 0.42, 0.55, 0.08, 0.15
UPPER_ARM, FOREARM, HAND, FOOT, TOE = 0.30, 0.26, 0.08, 0.13, 0.06
HIP_HALF, SHOULDER_HALF = 0.09, 0.18
ANKLE_HEIGHT = 0.08

NAMES = (
    "pelvis", "spine", "chest", "neck", "head", "head_end",
    "left_shoulder", "left_elbow", "left_wrist", "left_hand_end",
    "right_shoulder", "right_elbow", "right_wrist", "right_hand_end",
    "left_hip", "left_knee", "left_ankle", "left_toe", "left_toe_end",
    "right_hip", "right_knee", "right_ankle", "right_toe", "right_toe_end",
)  # fmt: skip
PARENTS = (
    "", "pelvis", "spine", "chest", "neck", "head",
    "chest", "left_shoulder", "left_elbow", "left_wrist",
    "chest", "right_shoulder", "right_elbow", "right_wrist",
    "pelvis", "left_hip", "left_knee", "left_ankle", "left_toe",
    "pelvis", "right_hip", "right_knee", "right_ankle", "right_toe",
)  # fmt: skip


def _smooth(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def all_fours_motion(
    fps: float = 60.0, stand: float = 1.0, down: float = 1.5, hold: float = 2.0, wrist_height: float = 0.04
) -> Motion:
    """The motion described in the module docstring (a positional :class:`Motion`)."""
    F = int(round((stand + down + hold) * fps))
    t = np.arange(F) / fps
    s = _smooth((t - stand) / down)  # 0 standing .. 1 on all fours
    sway = 0.01 * np.sin(2 * np.pi * 0.5 * np.maximum(t - stand - down, 0.0))
    # shank angle from vertical (rotating back about the ankle), final: lying on the floor
    beta = s * np.pi / 2
    knee_x = SHANK * np.sin(beta)
    knee_z = ANKLE_HEIGHT + SHANK * np.cos(beta)
    hip_x, hip_z = knee_x + sway, knee_z + THIGH  # thigh vertical
    # trunk pitch from vertical so that, at the end, the hanging arms reach the floor
    shoulder_z_end = wrist_height + UPPER_ARM + FOREARM
    pitch_end = np.arccos((shoulder_z_end - (ANKLE_HEIGHT + THIGH)) / TRUNK)
    pitch = s * pitch_end
    fwd = np.stack([np.sin(pitch), np.cos(pitch)], axis=1)  # trunk direction (x, z)
    P = {n: np.zeros((F, 3)) for n in NAMES}

    def put(name: str, x, z, y: float = 0.0) -> None:
        P[name][:, 0], P[name][:, 1], P[name][:, 2] = x, y, z

    put("pelvis", hip_x, hip_z)
    put("spine", hip_x + 0.45 * TRUNK * fwd[:, 0], hip_z + 0.45 * TRUNK * fwd[:, 1])
    put("chest", hip_x + 0.75 * TRUNK * fwd[:, 0], hip_z + 0.75 * TRUNK * fwd[:, 1])
    nx, nz = hip_x + TRUNK * fwd[:, 0], hip_z + TRUNK * fwd[:, 1]
    put("neck", nx, nz)
    put("head", nx + NECK * fwd[:, 0], nz + NECK * fwd[:, 1])
    put("head_end", nx + (NECK + HEAD) * fwd[:, 0], nz + (NECK + HEAD) * fwd[:, 1])
    # toes: forward and flat standing, pointing back (plantar-flexed) on all fours
    foot_angle = s * np.pi * 0.9  # direction of the foot from +X, rotating down and back
    fx, fz = np.cos(foot_angle), -np.abs(np.sin(foot_angle)) * 0.35
    for side, y in (("left", HIP_HALF), ("right", -HIP_HALF)):
        put(f"{side}_hip", hip_x, hip_z, y)
        put(f"{side}_knee", knee_x + sway, knee_z, y)
        put(f"{side}_ankle", 0.0, ANKLE_HEIGHT, y)
        n = np.hypot(fx, fz)
        tx, tz = FOOT * fx / n, np.maximum(ANKLE_HEIGHT + FOOT * fz / n, 0.02) - ANKLE_HEIGHT
        put(f"{side}_toe", tx, ANKLE_HEIGHT + tz, y)
        put(f"{side}_toe_end", tx + TOE * np.sign(fx + 1e-9), ANKLE_HEIGHT + tz, y)
    for side, y in (("left", SHOULDER_HALF), ("right", -SHOULDER_HALF)):
        sx, sz = nx - 0.03 * fwd[:, 0], nz - 0.03 * fwd[:, 1]
        put(f"{side}_shoulder", sx, sz, y)
        put(f"{side}_elbow", sx, sz - UPPER_ARM, y)
        put(f"{side}_wrist", sx, sz - UPPER_ARM - FOREARM, y)
        put(f"{side}_hand_end", sx + HAND * s, sz - UPPER_ARM - FOREARM - HAND * (1 - s) - 0.02 * s, y)
    positions = np.stack([P[n] for n in NAMES], axis=1)
    parents = np.array([-1 if p == "" else NAMES.index(p) for p in PARENTS])
    rest = positions[0]
    offsets = np.array([rest[j] - (rest[parents[j]] if parents[j] >= 0 else 0.0) for j in range(len(NAMES))])
    skeleton = Skeleton(NAMES, parents, offsets)
    return Motion(skeleton=skeleton, fps=float(fps), positions=positions, source="all_fours")
