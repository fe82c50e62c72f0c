"""BVH of the retargeted character, built from its MJCF body tree.

Hierarchy: one BVH joint per body that carries degrees of freedom (bodies
welded to their parent are merged into it), the free-joint body as ROOT, and
an End Site at every leaf (at the farthest site or geom of the leaf's subtree).
Offsets are the rest pose's body positions relative to the parent.

Rotations: with :math:`R_b(t)` the world rotation of body :math:`b` and
:math:`R_b^0` its rest rotation, the BVH joint's world rotation is
:math:`D_b(t) = R_b(t) (R_b^0)^{-1}` (identity in the rest pose, as BVH
requires), and its channel rotation is :math:`D_{p}(t)^{-1} D_b(t)`.  Forward
kinematics of the file then gives back every body origin exactly:
:math:`x_b = x_p + D_p (x_b^0 - x_p^0)`, provided each body's joints pivot at
the body origin (true of the bundled characters; :func:`character_motion`
warns otherwise).

Channel order: where a body's hinges are about distinct principal axes (the
default humanoid), the rotation channels follow the hinge order of the MJCF,
so the channel values are the joint angles (sign flipped for an axis that the
Y-up conversion reverses).  Other bodies use ``rotation_order``.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from ..errors import warn
from ..motion import Motion, Skeleton
from ..rotations import quat_conj, quat_mul, up_axis_matrix, wxyz_to_xyzw
from ..spill import release
from ..trajectory import Trajectory

#: Frames whose world rotations are held at once while the local ones are derived.
BLOCK_FRAMES = 8192

__all__ = ["character_skeleton", "character_motion", "write_character_bvh"]


def _exported_bodies(model: mujoco.MjModel) -> list[int]:
    """Bodies that become BVH joints: every body with joints (world excluded)."""
    return [b for b in range(1, model.nbody) if model.body_jntnum[b] > 0]


def _leaf_tip(model: mujoco.MjModel, data: mujoco.MjData, body: int, exported: set[int]) -> np.ndarray | None:
    """Farthest site or geom centre in ``body``'s subtree not below another exported body."""
    def owned(b: int) -> bool:
        while b != body:
            if b in exported or b == 0:
                return False
            b = int(model.body_parentid[b])
        return True

    pts = [data.site_xpos[s] for s in range(model.nsite) if owned(int(model.site_bodyid[s]))]
    pts += [data.geom_xpos[g] for g in range(model.ngeom) if owned(int(model.geom_bodyid[g]))]
    if not pts:
        return None
    pts = np.array(pts)
    d = np.linalg.norm(pts - data.xpos[body], axis=1)
    if d.max() < 1e-4:
        return None
    return pts[int(np.argmax(d))] - data.xpos[body]


def character_skeleton(character) -> tuple[Skeleton, list[int], mujoco.MjData]:
    """The BVH skeleton of a character (metres, Z-up) and the MuJoCo body of each joint."""
    model = character.model
    data = character.rest_data()
    bodies = _exported_bodies(model)
    exported = set(bodies)
    names, parents, offsets, end, body_of = [], [], [], [], []
    index: dict[int, int] = {}
    for b in bodies:
        p = int(model.body_parentid[b])
        while p != 0 and p not in exported:
            p = int(model.body_parentid[p])
        index[b] = len(names)
        names.append(model.body(b).name or f"body{b}")
        parents.append(-1 if p == 0 else index[p])
        offsets.append(data.xpos[b] - (0.0 if p == 0 else data.xpos[p]))
        end.append(False)
        body_of.append(b)
        # hinge anchors away from the body origin would break the BVH's pivots
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            if int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_FREE) and np.linalg.norm(model.jnt_pos[j]) > 1e-6:
                warn(f"joint {model.joint(j).name!r} does not pivot at its body origin; the BVH pivots there")
    # end sites for leaves
    leaves = [b for b in bodies if not any(parents[index[c]] == index[b] for c in bodies if c != b)]
    for b in leaves:
        tip = _leaf_tip(model, data, b, exported)
        if tip is None:
            continue
        names.append(f"{names[index[b]]}_End")
        parents.append(index[b])
        offsets.append(tip)
        end.append(True)
        body_of.append(-1)
    # keep parents before children: end sites were appended after all bodies, which is fine
    skel = Skeleton(tuple(names), np.array(parents), np.array(offsets), np.array(end))
    return skel, body_of, data


def _channel_order(model: mujoco.MjModel, body: int, up: str, default: str) -> str:
    """Rotation channel order that makes channel values equal the body's hinge angles."""
    C = up_axis_matrix("Z", up)
    axes = []
    for j in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
        if int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_HINGE):
            return default
        # hinge axis in world at rest (body frames are world-aligned for the default humanoid)
        axes.append(model.jnt_axis[j])
    if not axes:
        return default
    letters = []
    for a in axes:
        # the body's rest orientation may not be world-aligned: then fall back
        v = C @ a
        k = int(np.argmax(np.abs(v)))
        if abs(abs(v[k]) - 1.0) > 1e-6:
            return default
        letters.append("XYZ"[k])
    if len(set(letters)) != len(letters):
        return default
    for c in default:
        if c not in letters:
            letters.append(c)
    return "".join(letters[:3])


class _LocalRotations:
    """The BVH joints' local rotations and the root position of a trajectory, computed
    for any range of frames (see the module docstring for the maths)."""

    def __init__(self, traj: Trajectory, skel: Skeleton, body_of: list[int], rest: mujoco.MjData) -> None:
        self.traj = traj
        self.skel = skel
        self.root = body_of[0]
        self.data = mujoco.MjData(traj.model)
        self.bodies = np.array([b for b in body_of if b >= 0])
        self.cols = np.array([i for i, b in enumerate(body_of) if b >= 0])
        self.inv_rest = quat_conj(wxyz_to_xyzw(rest.xquat)[self.bodies])

    def rows(self, s: int, e: int) -> tuple[np.ndarray, np.ndarray]:
        """Frames ``[s, e)``: ``(local rotations (n, J, 4) x-y-z-w (identity on end sites),
        root positions (n, 1, 3) metres)``, world axes."""
        model, data = self.traj.model, self.data
        D = np.zeros((e - s, self.skel.num_joints, 4))
        D[..., 3] = 1.0
        root = np.zeros((e - s, 1, 3))
        for t in range(s, e):
            data.qpos[:] = self.traj.qpos[t]
            mujoco.mj_kinematics(model, data)
            D[t - s, self.cols] = quat_mul(wxyz_to_xyzw(data.xquat[self.bodies]), self.inv_rest)
            root[t - s, 0] = data.xpos[self.root]
        release(self.traj.qpos)  # a spilled trajectory: the frames read leave the memory
        local = D.copy()
        for j in range(self.skel.num_joints):
            p = int(self.skel.parents[j])
            if p >= 0:
                local[:, j] = quat_mul(quat_conj(D[:, p]), D[:, j])
        local[:, self.skel.end_site] = np.array([0.0, 0.0, 0.0, 1.0])
        return local, root


def _channels(model: mujoco.MjModel, skel: Skeleton, body_of: list[int], up: str, rotation_order: str) -> dict[str, list[str]]:
    """Joint name -> BVH channels for a file with ``up`` as its up axis: the root's three
    positions, then every body's three rotations (:func:`_channel_order`)."""
    channels = {}
    for j in range(skel.num_joints):
        if body_of[j] < 0:
            continue
        rot = [f"{a}rotation" for a in _channel_order(model, body_of[j], up, rotation_order)]
        channels[skel.names[j]] = (["Xposition", "Yposition", "Zposition"] if j == 0 else []) + rot
    return channels


def character_motion(traj: Trajectory, up: str = "Y", rotation_order: str = "ZXY") -> Motion:
    """The character's trajectory as a rotational :class:`Motion` (metres, Z-up).

    ``meta["bvh_channels"]`` holds the per-joint channel list chosen for a
    file written with ``up`` as its up axis (read by :func:`~physmocap.export.bvh.write_bvh`).
    """
    character = traj.character
    skel, body_of, rest = character_skeleton(character)
    frames = _LocalRotations(traj, skel, body_of, rest)
    F = traj.num_frames
    local = np.empty((F, skel.num_joints, 4))
    root_pos = np.empty((F, 1, 3))
    for s in range(0, F, BLOCK_FRAMES):  # the world rotations D are held a block at a time
        e = min(F, s + BLOCK_FRAMES)
        local[s:e], root_pos[s:e] = frames.rows(s, e)
    return Motion(
        skeleton=skel,
        fps=traj.fps,
        rotations=local,
        translations=root_pos,
        translated=np.array([0]),
        source=str(traj.source),
        units="m",
        unit_scale=1.0,
        file_up=up,
        meta={"bvh_channels": _channels(character.model, skel, body_of, up, rotation_order),
              "character": str(character.name)},
    )


def write_character_bvh(
    traj: Trajectory,
    path: str | os.PathLike,
    up: str = "Y",
    units: str | float = "m",
    rotation_order: str = "ZXY",
    precision: int = 6,
) -> Path:
    """Write the character's motion as BVH (atomically); see the module docstring.

    The rotations are computed a block of frames at a time while the file is written
    (never the whole clip's); the bytes are those of ``write_bvh(character_motion(traj))``.
    """
    from .bvh import check_bvh_options, write_bvh_rows

    check_bvh_options(rotation_order, precision, units, up)
    up = str(up).strip().upper()
    skel, body_of, rest = character_skeleton(traj.character)
    frames = _LocalRotations(traj, skel, body_of, rest)
    channels = _channels(traj.model, skel, body_of, up, rotation_order)
    return write_bvh_rows(path, skel, np.array([0]), channels, traj.num_frames, traj.fps, frames.rows,
                          precision=precision, units=units, up=up)
