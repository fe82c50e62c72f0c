"""Robot-learning exports: the layouts motion-tracking pipelines read.

**robot CSV** (``--format robot-csv``; the layout of Unitree's public retargeted LAFAN1 CSVs):
no header, one row per frame at the clip's rate, comma-separated::

    root_x, root_y, root_z, root_qx, root_qy, root_qz, root_qw, q_1, ..., q_D

root position in metres (world, Z-up), root orientation as a quaternion **x-y-z-w**, then the
hinge/slide joint positions (radians / metres) in the model's joint order.  The joint order is
in the ``.joints.txt`` file written beside it (one name per line), so no order is implicit.

**robot NPZ** (``--format robot-npz``), every array named, no paths, no pickle:

====================  =========================================================
``fps``               scalar, frames per second
``root_pos``          ``(F, 3)`` root position, metres, world Z-up
``root_quat_wxyz``    ``(F, 4)`` root orientation, w-x-y-z
``dof_names``         ``(D,)`` hinge/slide joint names, model order
``dof_pos``           ``(F, D)`` joint positions (radians / metres)
``joint_vel``         ``(F, D)`` joint velocities (central differences; one-sided at the ends)
``body_names``        ``(B,)`` every body but the world, model order
``body_pos_w``        ``(F, B, 3)`` body origins in the world, metres
``body_quat_w``       ``(F, B, 4)`` body orientations in the world, w-x-y-z
====================  =========================================================
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from ..errors import OutputError
from ..fileio import OutputSet, atomic_open
from ..rotations import wxyz_to_xyzw
from ..trajectory import Trajectory
from .trajectory import write_npz

__all__ = ["robot_arrays", "write_robot_csv", "write_robot_npz"]


def _layout(model: mujoco.MjModel) -> tuple[int, list[int], list[str]]:
    """(qpos address of the free root or -1, qpos addresses of the hinge/slide joints, their names)."""
    root = -1
    adr, names = [], []
    for j in range(model.njnt):
        t = int(model.jnt_type[j])
        if t == int(mujoco.mjtJoint.mjJNT_FREE) and root < 0:
            root = int(model.jnt_qposadr[j])
        elif t in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            adr.append(int(model.jnt_qposadr[j]))
            names.append(model.joint(j).name)
    return root, adr, names


def robot_arrays(traj: Trajectory) -> dict[str, np.ndarray]:
    """The arrays of the robot NPZ (module docstring)."""
    model = traj.character.model
    root, adr, names = _layout(model)
    if root < 0:
        raise OutputError("the character has no free root joint: robot outputs need one")
    q = np.asarray(traj.qpos, dtype=float)
    dof = q[:, adr]
    vel = np.gradient(dof, axis=0) * traj.fps if len(q) > 1 else np.zeros_like(dof)
    data = mujoco.MjData(model)
    B = model.nbody - 1
    pos = np.empty((len(q), B, 3))
    quat = np.empty((len(q), B, 4))
    for t, row in enumerate(q):
        data.qpos[:] = row
        mujoco.mj_kinematics(model, data)
        pos[t] = data.xpos[1:]
        quat[t] = data.xquat[1:]
    return {
        "fps": np.float64(traj.fps),
        "root_pos": q[:, root : root + 3],
        "root_quat_wxyz": q[:, root + 3 : root + 7],
        "dof_names": np.array(names),
        "dof_pos": dof,
        "joint_vel": vel,
        "body_names": np.array([model.body(b).name for b in range(1, model.nbody)]),
        "body_pos_w": pos,
        "body_quat_w": quat,
    }


def _finite(arrays: dict[str, np.ndarray], path: Path) -> None:
    for k, v in arrays.items():
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            raise OutputError(f"non-finite values in {k}: nothing written", path=path)


def write_robot_npz(traj: Trajectory, path: str | os.PathLike) -> Path:
    """Write the robot NPZ (deterministic bytes, atomic)."""
    arrays = robot_arrays(traj)
    _finite(arrays, Path(path))
    return write_npz(path, arrays)


def write_robot_csv(traj: Trajectory, path: str | os.PathLike, precision: int = 9) -> Path:
    """Write the robot CSV and, beside it, ``<stem>.joints.txt`` with the joint order."""
    p = Path(path)
    model = traj.character.model
    root, adr, names = _layout(model)
    if root < 0:
        raise OutputError("the character has no free root joint: robot outputs need one", path=p)
    q = np.asarray(traj.qpos, dtype=float)
    rows = np.concatenate([q[:, root : root + 3], wxyz_to_xyzw(q[:, root + 3 : root + 7]), q[:, adr]], axis=1)
    if not np.all(np.isfinite(rows)):
        raise OutputError("non-finite joint positions: nothing written", path=p)
    fmt = f"{{:.{int(precision)}g}}"
    names_path = p.with_name(p.stem + ".joints.txt")
    with OutputSet():  # the CSV and its joint names renamed into place together, or neither
        with atomic_open(names_path) as fh:
            fh.write("\n".join(["root_x", "root_y", "root_z", "root_qx", "root_qy", "root_qz", "root_qw", *names]) + "\n")
        with atomic_open(p) as fh:
            for row in rows:
                fh.write(",".join(fmt.format(v) for v in row) + "\n")
    return p
