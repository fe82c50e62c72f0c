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
``map_path``        the character's mapping file, relative to the NPZ's folder;
                    ``""`` when none was used or it is the bundled one the MJCF
                    finds by itself (``physmocap report`` reloads the character
                    with it unless given ``--map``)
``character``       the character's name
``source``          the input motion: ``example``, or its path relative to the NPZ's folder
``source_start``    the source frame the trajectory's frame 0 came from
``target_*``        the IK targets (``target_names`` (N,), ``target_positions``
                    (F, N, 3) metres, ``target_orientations`` (F, N, 4) x-y-z-w,
                    ``target_has_orientation`` (N,), ``target_valid`` (F, N)),
                    so ``physmocap report`` measures tracking against exactly
                    what the retargeter tracked; ``target_scale``: the root
                    scale (character leg over the actor's) the targets used
==================  ==========================================================

The file is a zip archive written with fixed timestamps, so the same
trajectory always gives the same bytes (``np.savez`` stamps the wall clock).

CSV: a header ``frame,time,<qpos_names...>`` then one row per frame.
"""

from __future__ import annotations

import io
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import mujoco
import numpy as np

from ..errors import OutputError
from ..fileio import atomic_open
from ..spill import blocks, release
from ..trajectory import Trajectory

__all__ = ["ArrayBlocks", "write_npz", "write_trajectory_npz", "write_trajectory_csv", "qvel_from_qpos", "qvel_blocks"]

_JOINT_TYPES = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}


#: Rows of a large array converted and written at a time (NPZ members, velocities, checks).
BLOCK_ROWS = 8192


@dataclass(frozen=True)
class ArrayBlocks:
    """An array an NPZ writer writes block by block without ever holding it whole: its
    ``shape`` and ``dtype``, and ``blocks()``, which yields C-ordered row blocks that
    together make the array (their first dimensions sum to ``shape[0]``)."""

    shape: tuple[int, ...]
    dtype: np.dtype
    blocks: Callable[[], Iterator[np.ndarray]]


def write_npz(path: str | os.PathLike, arrays: dict[str, "np.ndarray | ArrayBlocks"]) -> Path:
    """Write ``arrays`` as an uncompressed ``.npz`` with deterministic bytes, atomically.

    Each member is a ``.npy`` file (format 1.0 header) streamed into the archive: an array by
    ``np.lib.format.write_array`` straight into the member (no in-memory copy of the file),
    an :class:`ArrayBlocks` a block of rows at a time.  The bytes are those of ``np.save``
    into ``ZipFile.writestr`` with a fixed timestamp.
    """
    p = Path(path)
    with atomic_open(p, "wb") as fh:
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED) as zf:
            for name, value in arrays.items():
                _write_member(zf, name, value, p)
    return p


def _write_member(zf: zipfile.ZipFile, name: str, value: "np.ndarray | ArrayBlocks", path: Path) -> None:
    """One ``<name>.npy`` member of a known size (so the archive's bytes do not depend on
    how it is streamed): the header, then the data."""
    arr = value if isinstance(value, ArrayBlocks) else np.asarray(value)
    if arr.dtype == object:
        raise OutputError(f"array {name!r} has object dtype, which needs pickle", path=path)
    header = io.BytesIO()
    if isinstance(arr, ArrayBlocks):
        fields = {"descr": np.lib.format.dtype_to_descr(arr.dtype), "fortran_order": False, "shape": tuple(arr.shape)}
    else:
        fields = np.lib.format.header_data_from_array_1_0(arr)
    np.lib.format.write_array_header_1_0(header, fields)
    info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o644 << 16
    info.compress_type = zipfile.ZIP_STORED
    info.file_size = len(header.getvalue()) + int(np.prod(arr.shape, dtype=np.int64)) * arr.dtype.itemsize
    with zf.open(info, mode="w") as dest:
        if not isinstance(arr, ArrayBlocks):
            np.lib.format.write_array(dest, arr, allow_pickle=False)
            return
        dest.write(header.getvalue())
        for block in arr.blocks():
            dest.write(np.ascontiguousarray(block, dtype=arr.dtype).tobytes())


def qvel_blocks(model: mujoco.MjModel, qpos: np.ndarray, fps: float, rows: int = BLOCK_ROWS) -> Iterator[np.ndarray]:
    """Backward-difference generalised velocities (``mj_differentiatePos``: the velocity
    that integrates ``qpos[t-1]`` to ``qpos[t]`` in ``1/fps`` seconds) in ``(rows, nv)``
    blocks; frame 0 is zero."""
    F = qpos.shape[0]
    for s in range(0, F, rows):
        block = np.zeros((min(F, s + rows) - s, model.nv))
        for t in range(max(s, 1), s + block.shape[0]):
            mujoco.mj_differentiatePos(model, block[t - s], 1.0 / fps, qpos[t - 1], qpos[t])
        release(qpos)
        yield block


def qvel_from_qpos(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> np.ndarray:
    """Backward-difference generalised velocities ``(F, nv)``; frame 0 is zero (:func:`qvel_blocks`)."""
    return np.concatenate([np.zeros((0, model.nv)), *qvel_blocks(model, qpos, fps)])


def row_blocks(array: np.ndarray) -> ArrayBlocks:
    """``array`` (float64, C order) as :class:`ArrayBlocks` of rows (:func:`~physmocap.spill.blocks`):
    a spilled array (:mod:`physmocap.spill`) is written holding one block of it."""
    return ArrayBlocks(tuple(array.shape), np.dtype(np.float64), lambda: (b for _, b in blocks(array)))


def _check_finite(traj: Trajectory, path: Path) -> None:
    """Refuse a trajectory with a non-finite number (checked a block of frames at a time)."""
    for s, rows in blocks(traj.qpos):
        bad = ~np.all(np.isfinite(rows), axis=1)
        if np.any(bad):
            raise OutputError(
                f"trajectory has non-finite values on frame {s + int(np.argmax(bad))}; nothing written",
                path=path,
            )


def trajectory_arrays(traj: Trajectory, base: Path | None = None) -> dict[str, "np.ndarray | ArrayBlocks"]:
    """The arrays :func:`write_trajectory_npz` stores (``qvel`` as :class:`ArrayBlocks`,
    computed while it is written); paths relative to ``base`` (the output's folder) or
    bundled names, never the machine's absolute paths."""
    from ..resources import portable_path

    base = Path(".") if base is None else base
    model = traj.model
    ch = traj.character
    return {
        "qpos": row_blocks(traj.qpos),
        "qvel": ArrayBlocks((traj.num_frames, model.nv), np.dtype(np.float64),
                            lambda: qvel_blocks(model, traj.qpos, traj.fps)),
        "fps": np.float64(traj.fps),
        "qpos_names": np.array(traj.column_names),
        "joint_names": np.array([model.joint(j).name for j in range(model.njnt)]),
        "joint_types": np.array([_JOINT_TYPES[int(t)] for t in model.jnt_type]),
        "joint_qposadr": model.jnt_qposadr.astype(np.int64),
        "quat_convention": np.array("wxyz"),
        "mjcf_path": np.array(portable_path(ch.mjcf_path, base)),
        "map_path": np.array(stored_map_path(ch, base)),
        "character": np.array(str(ch.name)),
        "source": np.array(portable_path(traj.source, base)),
        "source_start": np.int64(traj.source_start),
        **target_arrays(traj.targets),
    }


def stored_map_path(character, base: Path) -> str:
    """How a trajectory NPZ names the character's mapping file (its ``map_path``): ``""`` for
    none (the model's own names or a proposed mapping) or for the mapping bundled with physmocap
    that the MJCF finds without ``--map``; else the file's path relative to ``base`` (the NPZ's
    folder), so no absolute path of this machine enters the file."""
    from ..models.character import default_map_file
    from ..resources import mjcf_dir, portable_path

    given = getattr(character, "map_path", None)
    if given is None:
        return ""
    mp = Path(given).resolve()
    found = default_map_file(character.mjcf_path)
    if found is not None and found.resolve() == mp and mp.is_relative_to(mjcf_dir().resolve()):
        return ""
    return portable_path(given, base)


def target_arrays(targets) -> "dict[str, np.ndarray | ArrayBlocks]":
    """The ``target_*`` arrays of a trajectory NPZ (empty without targets)."""
    if targets is None:
        return {}
    return {
        "target_names": np.array(list(targets.names)),
        "target_positions": row_blocks(targets.positions),
        "target_orientations": row_blocks(targets.orientations),
        "target_has_orientation": np.asarray(targets.has_orientation, dtype=bool),
        "target_valid": np.asarray(targets.valid, dtype=bool),
        "target_scale": np.float64(targets.scale),
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
