"""Joint-trajectory exports for simulation and robot learning: ``.npz`` and ``.csv``.

NPZ contents (all plain arrays, loadable with ``np.load(path)`` and
``allow_pickle=False``):

==================  ==========================================================
``qpos``            ``(F, nq)`` float64, MuJoCo order; free-joint orientation
                    is a quaternion **w, x, y, z** (MuJoCo's convention)
``qvel``            ``(F, nv)`` float64, finite-difference velocities
                    (``mj_differentiatePos``, backward difference, 0 on frame 0)
``fps``             scalar float64
``qpos_names``      ``(nq,)`` column names (``root_x .. root_qw root_qx ..``)
``joint_names``     ``(njnt,)`` MuJoCo joint names
``joint_types``     ``(njnt,)`` ``free``, ``ball``, ``slide`` or ``hinge``
``joint_qposadr``   ``(njnt,)`` first qpos column of each joint
``quat_convention`` ``"wxyz"``
``mjcf_path``       the character's MJCF file: a bundled character's name, or the
                    path relative to the NPZ's folder
``character``       the character's name
``source``          the input motion: ``example``, or its path relative to the NPZ's folder
``source_start``    the source frame the trajectory's frame 0 came from
``target_*``        the IK targets (``target_names`` (N,), ``target_positions``
                    (F, N, 3) metres, ``target_orientations`` (F, N, 4) x-y-z-w,
                    ``target_has_orientation`` (N,), ``target_valid`` (F, N)),
                    so ``physmocap report`` measures tracking against exactly
                    what the retargeter tracked
==================  ==========================================================

The file is a zip archive written with fixed timestamps, so the same
trajectory always gives the same bytes (``np.savez`` stamps the wall clock).

CSV: a header ``frame,time,<qpos_names...>`` then one row per frame.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import mujoco
import numpy as np

from ..errors import OutputError
from ..fileio import atomic_open
from ..trajectory import Trajectory

__all__ = ["write_npz", "write_trajectory_npz", "write_trajectory_csv", "qvel_from_qpos"]

_JOINT_TYPES = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}


def write_npz(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> Path:
    """Write ``arrays`` as an uncompressed ``.npz`` with deterministic bytes, atomically."""
    p = Path(path)
    with atomic_open(p, "wb") as fh:
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED) as zf:
            for name, value in arrays.items():
                arr = np.asarray(value)
                if arr.dtype == object:
                    raise OutputError(f"array {name!r} has object dtype, which needs pickle", path=p)
                buf = io.BytesIO()
                np.lib.format.write_array(buf, arr, allow_pickle=False)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue())
    return p


def qvel_from_qpos(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> np.ndarray:
    """Backward-difference generalised velocities ``(F, nv)``; frame 0 is zero."""
    F = qpos.shape[0]
    qvel = np.zeros((F, model.nv))
    for t in range(1, F):
        mujoco.mj_differentiatePos(model, qvel[t], 1.0 / fps, qpos[t - 1], qpos[t])
    return qvel


def _check_finite(traj: Trajectory, path: Path) -> None:
    bad = ~np.all(np.isfinite(traj.qpos), axis=1)
    if np.any(bad):
        raise OutputError(
            f"trajectory has non-finite values on frame {int(np.argmax(bad))}; nothing written",
            path=path,
        )


def trajectory_arrays(traj: Trajectory, base: Path | None = None) -> dict[str, np.ndarray]:
    """The arrays :func:`write_trajectory_npz` stores; paths relative to ``base`` (the
    output's folder) or bundled names, never the machine's absolute paths."""
    from ..resources import portable_path

    base = Path(".") if base is None else base
    model = traj.model
    ch = traj.character
    return {
        "qpos": np.ascontiguousarray(traj.qpos, dtype=np.float64),
        "qvel": qvel_from_qpos(model, traj.qpos, traj.fps),
        "fps": np.float64(traj.fps),
        "qpos_names": np.array(traj.column_names),
        "joint_names": np.array([model.joint(j).name for j in range(model.njnt)]),
        "joint_types": np.array([_JOINT_TYPES[int(t)] for t in model.jnt_type]),
        "joint_qposadr": model.jnt_qposadr.astype(np.int64),
        "quat_convention": np.array("wxyz"),
        "mjcf_path": np.array(portable_path(ch.mjcf_path, base)),
        "character": np.array(str(ch.name)),
        "source": np.array(portable_path(traj.source, base)),
        "source_start": np.int64(traj.source_start),
        **target_arrays(traj.targets),
    }


def target_arrays(targets) -> dict[str, np.ndarray]:
    """The ``target_*`` arrays of a trajectory NPZ (empty without targets)."""
    if targets is None:
        return {}
    return {
        "target_names": np.array(list(targets.names)),
        "target_positions": np.ascontiguousarray(targets.positions, dtype=np.float64),
        "target_orientations": np.ascontiguousarray(targets.orientations, dtype=np.float64),
        "target_has_orientation": np.asarray(targets.has_orientation, dtype=bool),
        "target_valid": np.asarray(targets.valid, dtype=bool),
    }


def write_trajectory_npz(traj: Trajectory, path: str | os.PathLike) -> Path:
    """Write the trajectory as ``.npz`` (see the module docstring for the keys)."""
    p = Path(path)
    _check_finite(traj, p)
    return write_npz(p, trajectory_arrays(traj, p.parent))


def write_trajectory_csv(traj: Trajectory, path: str | os.PathLike, precision: int = 9) -> Path:
    """Write ``frame,time,<qpos columns>`` rows (quaternions w, x, y, z), atomically."""
    p = Path(path)
    _check_finite(traj, p)
    fmt = f"{{:.{int(precision)}g}}"
    with atomic_open(p, "w") as fh:
        fh.write(",".join(["frame", "time", *traj.column_names]) + "\n")
        for t, row in enumerate(traj.qpos):
            vals = ",".join(fmt.format(v) for v in row)
            fh.write(f"{t},{fmt.format(t / traj.fps)},{vals}\n")
    return p
