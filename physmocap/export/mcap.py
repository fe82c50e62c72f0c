"""Write skeleton recordings as MCAP that Foxglove shows without plugins.

Layout of a file (one or more *tracks*, i.e. skeletons, each under its own
topic prefix ``P``, e.g. ``/skeleton`` for a source and ``/character`` for a
retargeted character):

* ``P/tf``: ``foxglove.FrameTransforms``, one message per frame holding one
  transform per joint from its parent's frame to its own (the root's parent
  is the shared world frame ``world``).  Frame ids are ``<P without the
  leading slash>/<joint>`` so several skeletons coexist in one transform tree.
* ``P/joints``: ``physmocap.JointPositions`` (this module's JSON schema): the
  world position of every joint by name, and its confidence when known.
* ``P/poses`` (optional): ``foxglove.PosesInFrame`` with every joint's world
  pose, in joint order.
* A metadata record ``physmocap.skeleton`` per track with the hierarchy,
  rest offsets, units (``m``), up axis (``Z``), fps and frame count, so
  :func:`physmocap.sources.mcap.read_mcap` rebuilds the same motion.

Messages use JSON encoding with ``jsonschema`` schemas written to match
Foxglove's published JSON schemas (foxglove/schemas, ``schemas/jsonschema``:
FrameTransforms.json, FrameTransform.json, PosesInFrame.json).  Lengths are
metres, the world is Z-up (Foxglove's convention as well as physmocap's),
quaternions x-y-z-w.  Frame ``i`` is stamped ``start_time_ns + round(i * 1e9 / fps)``
nanoseconds; no wall-clock time and a fixed library string make the output
bytes a function of the input.  Floats are written with Python's ``repr``
(shortest round-trip form), so reading back is exact.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import __version__
from ..errors import OptionError, OutputError
from ..fileio import atomic_open
from ..motion import Motion
from ..rotations import quat_apply, quat_conj, quat_mul

__all__ = [
    "TransformTrack",
    "track_from_motion",
    "track_from_world_poses",
    "write_transforms_mcap",
    "write_motion_mcap",
    "write_trajectory_mcap",
    "frame_time_ns",
    "FRAME_TRANSFORMS_SCHEMA",
    "LABELLED_POINTS_SCHEMA",
    "MARKERS_METADATA",
    "write_markers_mcap",
    "write_markers_pointcloud_mcap",
    "POINT_CLOUD_SCHEMA",
    "POSES_IN_FRAME_SCHEMA",
    "JOINT_POSITIONS_SCHEMA",
    "SKELETON_METADATA",
    "WORLD_FRAME",
    "LIBRARY",
]

WORLD_FRAME = "world"
SKELETON_METADATA = "physmocap.skeleton"
METADATA_FORMAT = "physmocap.skeleton/1"
LIBRARY = f"physmocap {__version__}"


# --- schemas -----------------------------------------------------------------------
def _time_schema(description: str) -> dict:
    return {
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
        },
        "description": description,
    }


def _vector3_schema(description: str) -> dict:
    return {
        "title": "foxglove.Vector3",
        "description": description,
        "type": "object",
        "properties": {
            axis: {"type": "number", "description": f"{axis} coordinate length"} for axis in "xyz"
        },
    }


def _quaternion_schema(description: str) -> dict:
    return {
        "title": "foxglove.Quaternion",
        "description": description,
        "type": "object",
        "properties": {c: {"type": "number", "description": f"{c} value"} for c in "xyzw"},
    }


def _frame_transform_schema() -> dict:
    return {
        "title": "foxglove.FrameTransform",
        "description": "A transform between two reference frames in 3D space",
        "type": "object",
        "properties": {
            "timestamp": _time_schema("Timestamp of transform"),
            "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
            "child_frame_id": {"type": "string", "description": "Name of the child frame"},
            "translation": _vector3_schema("Translation component of the transform"),
            "rotation": _quaternion_schema("Rotation component of the transform"),
        },
    }


#: ``foxglove.FrameTransforms`` (as published in foxglove/schemas, JSON schema flavour).
FRAME_TRANSFORMS_SCHEMA: dict = {
    "title": "foxglove.FrameTransforms",
    "description": "An array of FrameTransform messages",
    "type": "object",
    "properties": {
        "transforms": {
            "type": "array",
            "items": _frame_transform_schema(),
            "description": "Array of transforms",
        }
    },
}

#: ``foxglove.PosesInFrame`` (as published in foxglove/schemas).
POSES_IN_FRAME_SCHEMA: dict = {
    "title": "foxglove.PosesInFrame",
    "description": "An array of timestamped poses for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": _time_schema("Timestamp of pose"),
        "frame_id": {
            "type": "string",
            "description": "Frame of reference for pose position and orientation",
        },
        "poses": {
            "type": "array",
            "items": {
                "title": "foxglove.Pose",
                "description": "A position and orientation for an object or reference frame in 3D space",
                "type": "object",
                "properties": {
                    "position": _vector3_schema("Point denoting position in 3D space"),
                    "orientation": _quaternion_schema("Quaternion denoting orientation in 3D space"),
                },
            },
            "description": "Poses in 3D space",
        },
    },
}

_POINT = {
    "type": "object",
    "properties": {axis: {"type": "number"} for axis in "xyz"},
    "required": ["x", "y", "z"],
    "additionalProperties": False,
}

#: physmocap's own schema: world joint positions (metres, Z-up) by joint name.
JOINT_POSITIONS_SCHEMA: dict = {
    "title": "physmocap.JointPositions",
    "description": "World positions of a skeleton's joints by name, in metres, Z-up",
    "type": "object",
    "properties": {
        "timestamp": _time_schema("Timestamp of the frame"),
        "frame": {"type": "integer", "minimum": 0, "description": "0-based frame index"},
        "frame_id": {"type": "string", "description": "Frame the positions are expressed in"},
        "positions": {
            "type": "object",
            "additionalProperties": _POINT,
            "description": "Joint name -> position",
        },
        "confidence": {
            "type": "object",
            "additionalProperties": {"type": "number", "minimum": 0, "maximum": 1},
            "description": "Joint name -> tracking confidence in [0, 1] (0: not tracked)",
        },
    },
    "required": ["timestamp", "frame", "frame_id", "positions"],
}


#: physmocap's schema for optical markers: labelled points (metres, the recording's axes);
#: the frame fields of :data:`JOINT_POSITIONS_SCHEMA`, points by marker label.
LABELLED_POINTS_SCHEMA: dict = {
    "title": "physmocap.LabelledPoints",
    "description": "Labelled marker positions of one frame, in metres; a marker not seen on the frame is absent",
    "type": "object",
    "properties": {
        **{k: JOINT_POSITIONS_SCHEMA["properties"][k] for k in ("timestamp", "frame", "frame_id")},
        "points": {"type": "object", "additionalProperties": _POINT, "description": "Marker label -> position"},
    },
    "required": ["timestamp", "frame", "frame_id", "points"],
}
#: Metadata record naming a marker recording's labels, rate and source.
MARKERS_METADATA = "physmocap.markers"

#: ``foxglove.PointCloud`` (the fields physmocap writes, as in foxglove/schemas): packed
#: little-endian points, base64 ``data`` in JSON encoding.
POINT_CLOUD_SCHEMA: dict = {
    "title": "foxglove.PointCloud",
    "description": "A collection of N-dimensional points, which may contain additional fields with information like "
                   "normals, intensity, etc.",
    "type": "object",
    "properties": {
        "timestamp": _time_schema("Timestamp of point cloud"),
        "frame_id": {"type": "string", "description": "Frame of reference"},
        "pose": POSES_IN_FRAME_SCHEMA["properties"]["poses"]["items"],
        "point_stride": {"type": "integer", "minimum": 0, "description": "Number of bytes between points in the data"},
        "fields": {
            "type": "array",
            "items": {
                "title": "foxglove.PackedElementField",
                "type": "object",
                "properties": {"name": {"type": "string"}, "offset": {"type": "integer", "minimum": 0},
                               "type": {"type": "integer", "description": "NumericType: 8 is FLOAT64"}},
            },
            "description": "Fields in data",
        },
        "data": {"type": "string", "contentEncoding": "base64", "description": "Point data, interpreted using fields"},
    },
}
#: Foxglove ``NumericType`` of the coordinates written: FLOAT64.
_FLOAT64 = 8


def _schema_bytes(schema: dict) -> bytes:
    return json.dumps(schema, indent=2, sort_keys=False).encode("utf-8")


# --- tracks ------------------------------------------------------------------------
@dataclass(eq=False)
class TransformTrack:
    """One skeleton's transforms over frames, ready to write.

    Attributes:
        names: ``(N,)`` joint (or body) names, unique.
        parents: ``(N,)`` parent index per joint, ``-1`` for a root (child of the world frame).
        translations: ``(F, N, 3)`` translation of each joint in its parent's frame, metres.
        rotations: ``(F, N, 4)`` rotation of each joint relative to its parent, x-y-z-w.
        topic_prefix: Topic prefix, e.g. ``/skeleton``; also the frame-id prefix.
        positions: ``(F, N, 3)`` world positions for the joints channel; None
            computes them from the transforms.
        confidence: ``(F, N)`` confidence in [0, 1] for the joints channel, or None.
        role: ``"source"`` or ``"character"`` (readers pick the source by default).
        metadata: Extra entries for the track's metadata record (JSON-serialisable values).
    """

    names: Sequence[str]
    parents: np.ndarray
    translations: np.ndarray
    rotations: np.ndarray
    topic_prefix: str = "/skeleton"
    positions: np.ndarray | None = None
    confidence: np.ndarray | None = None
    role: str = "source"
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.names = tuple(str(n) for n in self.names)
        self.parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        self.translations = np.asarray(self.translations, dtype=float)
        self.rotations = np.asarray(self.rotations, dtype=float)
        N = len(self.names)
        F = self.translations.shape[0] if self.translations.ndim == 3 else -1
        if len(set(self.names)) != N:
            raise ValueError("track joint names must be unique")
        if self.parents.shape != (N,) or np.any(self.parents >= np.arange(N)) or np.any(self.parents < -1):
            raise ValueError("track parents must be (N,) with parents[j] < j (-1 for roots)")
        if self.translations.shape != (F, N, 3) or self.rotations.shape != (F, N, 4):
            raise ValueError(
                f"track arrays must be translations (F, {N}, 3) and rotations (F, {N}, 4), got "
                f"{self.translations.shape} and {self.rotations.shape}"
            )
        if self.positions is not None:
            self.positions = np.asarray(self.positions, dtype=float)
            if self.positions.shape != (F, N, 3):
                raise ValueError(f"track positions must be ({F}, {N}, 3)")
        if self.confidence is not None:
            self.confidence = np.asarray(self.confidence, dtype=float)
            if self.confidence.shape != (F, N):
                raise ValueError(f"track confidence must be ({F}, {N})")
        prefix = "/" + self.topic_prefix.strip("/")
        if prefix == "/":
            raise ValueError("topic_prefix must name something, e.g. '/skeleton'")
        self.topic_prefix = prefix

    @property
    def num_frames(self) -> int:
        return int(self.translations.shape[0])

    @property
    def frame_ids(self) -> tuple[str, ...]:
        base = self.topic_prefix.strip("/")
        return tuple(f"{base}/{n}" for n in self.names)

    def world_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """World ``(positions (F, N, 3), rotations (F, N, 4))`` by chaining the transforms."""
        F, N = self.translations.shape[:2]
        pos = np.empty((F, N, 3))
        rot = np.empty((F, N, 4))
        for j in range(N):
            p = int(self.parents[j])
            if p < 0:
                pos[:, j] = self.translations[:, j]
                rot[:, j] = self.rotations[:, j]
            else:
                pos[:, j] = pos[:, p] + quat_apply(rot[:, p], self.translations[:, j])
                rot[:, j] = quat_mul(rot[:, p], self.rotations[:, j])
        return pos, rot


def track_from_motion(
    motion: Motion, topic_prefix: str = "/skeleton", role: str = "source"
) -> TransformTrack:
    """The transforms of a :class:`Motion` (rotational or positional).

    Rotational: each joint's local rotation and its animated translation (the
    rest offset for joints without position channels).  Positional: frames
    stay aligned with the world (identity rotations) and each joint's
    translation is its position minus its parent's.
    """
    sk = motion.skeleton
    F, J = motion.num_frames, sk.num_joints
    meta: dict[str, Any] = {
        "kind": "rotational" if motion.is_rotational else "positional",
        "offsets": sk.offsets.tolist(),
        "end_site": [bool(x) for x in sk.end_site],
        "source": str(motion.source),
        "source_units": motion.units,
        "source_unit_scale": float(motion.unit_scale),
        "source_file_up": motion.file_up,
        "meta": motion.meta,
    }
    if motion.is_rotational:
        assert motion.rotations is not None and motion.translations is not None
        trans = np.broadcast_to(sk.offsets, (F, J, 3)).copy()
        if len(motion.translated):
            trans[:, motion.translated] = motion.translations
        rots = motion.rotations
        meta["translated"] = [int(k) for k in motion.translated]
        positions = None
    else:
        assert motion.positions is not None
        positions = motion.positions
        trans = positions.copy()
        has_parent = sk.parents >= 0
        trans[:, has_parent] -= positions[:, sk.parents[has_parent]]
        rots = np.zeros((F, J, 4))
        rots[..., 3] = 1.0
    return TransformTrack(
        names=sk.names,
        parents=sk.parents,
        translations=trans,
        rotations=rots,
        topic_prefix=topic_prefix,
        positions=positions,
        confidence=motion.confidence,
        role=role,
        metadata=meta,
    )


def track_from_world_poses(
    names: Sequence[str],
    parents: np.ndarray,
    positions: np.ndarray,
    rotations: np.ndarray | None = None,
    topic_prefix: str = "/character",
    role: str = "character",
    confidence: np.ndarray | None = None,
    metadata: dict[str, Any] | None = None,
) -> TransformTrack:
    """A track from world poses (e.g. a MuJoCo character's bodies).

    The local transform of joint ``j`` with parent ``p`` is
    :math:`R_j^{loc} = R_p^{-1} R_j`, :math:`t_j^{loc} = R_p^{-1}(x_j - x_p)`;
    with ``rotations`` None all frames are world-aligned.
    """
    positions = np.asarray(positions, dtype=float)
    F, N = positions.shape[:2]
    if rotations is None:
        rotations = np.zeros((F, N, 4))
        rotations[..., 3] = 1.0
    rotations = np.asarray(rotations, dtype=float)
    parents = np.asarray(parents, dtype=np.int64).reshape(-1)
    trans = positions.copy()
    rots = rotations.copy()
    for j in range(N):
        p = int(parents[j])
        if p >= 0:
            inv = quat_conj(rotations[:, p])
            trans[:, j] = quat_apply(inv, positions[:, j] - positions[:, p])
            rots[:, j] = quat_mul(inv, rotations[:, j])
    meta = {"kind": "rotational"}
    meta.update(metadata or {})
    return TransformTrack(
        names=names,
        parents=parents,
        translations=trans,
        rotations=rots,
        topic_prefix=topic_prefix,
        positions=positions,
        confidence=confidence,
        role=role,
        metadata=meta,
    )


# --- writing -----------------------------------------------------------------------
def frame_time_ns(frame: int, fps: float, start_time_ns: int = 0) -> int:
    """Timestamp in nanoseconds of frame ``frame`` at ``fps``."""
    return int(start_time_ns) + int(round(frame * 1e9 / fps))


def _stamp(t_ns: int) -> dict:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _check_finite(track: TransformTrack, path: Path) -> None:
    arrays = [("translation", track.translations), ("rotation", track.rotations)]
    if track.positions is not None:
        arrays.append(("position", track.positions))
    if track.confidence is not None:
        arrays.append(("confidence", track.confidence[..., None]))
    for what, arr in arrays:
        bad = ~np.all(np.isfinite(arr), axis=-1)
        if bad.any():
            f, j = (int(x) for x in np.argwhere(bad)[0])
            raise OutputError(
                f"refusing to write a non-finite {what} (frame {f}, joint {track.names[j]!r} "
                f"of {track.topic_prefix}; {int(bad.sum())} sample(s) in all)",
                path=path,
            )


def _json(obj: Any) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _jsonable(obj: Any) -> Any:
    """``json.dumps`` fallback: numpy scalars and arrays become numbers and lists."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, (set, tuple)):
        return list(obj)
    return str(obj)


def _metadata_record(track: TransformTrack, fps: float, start_time_ns: int, poses: bool) -> dict[str, str]:
    base = {
        "format": METADATA_FORMAT,
        "topic_prefix": track.topic_prefix,
        "role": track.role,
        "fps": repr(float(fps)),
        "num_frames": str(track.num_frames),
        "start_time_ns": str(int(start_time_ns)),
        "units": "m",
        "up_axis": "Z",
        "world_frame": WORLD_FRAME,
        "joints": json.dumps(list(track.names)),
        "frame_ids": json.dumps(list(track.frame_ids)),
        "parents": json.dumps([int(p) for p in track.parents]),
        "topics": json.dumps(
            {"tf": f"{track.topic_prefix}/tf", "joints": f"{track.topic_prefix}/joints"}
            | ({"poses": f"{track.topic_prefix}/poses"} if poses else {})
        ),
    }
    for key, value in track.metadata.items():
        if key in base:
            raise ValueError(f"metadata key {key!r} is reserved")
        try:
            base[key] = (
                value
                if isinstance(value, str)
                else json.dumps(value, sort_keys=True, allow_nan=False, default=_jsonable)
            )
        except (TypeError, ValueError) as exc:
            raise OutputError(f"track metadata {key!r} is not JSON-serialisable: {exc}") from None
    return base


def write_transforms_mcap(
    path: str | os.PathLike,
    tracks: Sequence[TransformTrack],
    fps: float,
    *,
    start_time_ns: int = 0,
    poses: bool = False,
    compression: str = "zstd",
) -> Path:
    """Write one or more skeleton tracks to an MCAP file (atomically).

    Args:
        path: Output ``.mcap`` path.
        tracks: The skeletons; all must have the same number of frames and
            distinct topic prefixes.
        fps: Frames per second (sets the timestamps).
        start_time_ns: Timestamp of frame 0 in nanoseconds.
        poses: Also write each track's world poses as ``foxglove.PosesInFrame``.
        compression: ``"zstd"``, ``"lz4"`` or ``"none"`` for the chunks.

    Raises:
        OutputError: non-finite values, mismatched tracks, unwritable path.
    """
    from mcap.writer import CompressionType, Writer

    p = Path(path)
    if not tracks:
        raise OutputError("no skeleton to write", path=p)
    if not (math.isfinite(fps) and fps > 0):
        raise OutputError(f"fps must be positive, got {fps}", path=p)
    if start_time_ns < 0:
        raise OutputError("start_time_ns must be >= 0", path=p)
    F = tracks[0].num_frames
    prefixes = [t.topic_prefix for t in tracks]
    if len(set(prefixes)) != len(prefixes):
        raise OutputError(f"tracks need distinct topic prefixes, got {prefixes}", path=p)
    for t in tracks:
        if t.num_frames != F:
            raise OutputError(
                f"all tracks need the same number of frames ({F}); {t.topic_prefix} has {t.num_frames}",
                path=p,
            )
        _check_finite(t, p)
    try:
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[
            compression
        ]
    except KeyError:
        raise OutputError(f"compression must be zstd, lz4 or none, got {compression!r}", path=p) from None

    with atomic_open(p, "wb") as fh:
        writer = Writer(fh, compression=comp, enable_data_crcs=True)
        writer.start(profile="", library=LIBRARY)
        tf_schema = writer.register_schema(
            "foxglove.FrameTransforms", "jsonschema", _schema_bytes(FRAME_TRANSFORMS_SCHEMA)
        )
        joints_schema = writer.register_schema(
            "physmocap.JointPositions", "jsonschema", _schema_bytes(JOINT_POSITIONS_SCHEMA)
        )
        poses_schema = (
            writer.register_schema("foxglove.PosesInFrame", "jsonschema", _schema_bytes(POSES_IN_FRAME_SCHEMA))
            if poses
            else 0
        )
        plan = []
        for t in tracks:
            world_pos, world_rot = t.world_poses()
            positions = t.positions if t.positions is not None else world_pos
            tf_ch = writer.register_channel(f"{t.topic_prefix}/tf", "json", tf_schema)
            j_ch = writer.register_channel(f"{t.topic_prefix}/joints", "json", joints_schema)
            p_ch = writer.register_channel(f"{t.topic_prefix}/poses", "json", poses_schema) if poses else 0
            record = _metadata_record(t, fps, start_time_ns, poses)
            if "source" in record:  # named relative to the output, never the machine's absolute path
                from ..resources import portable_path

                record["source"] = portable_path(record["source"], Path(path).parent)
            writer.add_metadata(SKELETON_METADATA, record)
            parent_ids = [WORLD_FRAME if q < 0 else t.frame_ids[q] for q in t.parents]
            plan.append((t, tf_ch, j_ch, p_ch, positions, world_pos, world_rot, parent_ids))

        for i in range(F):
            t_ns = frame_time_ns(i, fps, start_time_ns)
            stamp = _stamp(t_ns)
            for t, tf_ch, j_ch, p_ch, positions, world_pos, world_rot, parent_ids in plan:
                tr = t.translations[i].tolist()
                rq = t.rotations[i].tolist()
                msg = {
                    "transforms": [
                        {
                            "timestamp": stamp,
                            "parent_frame_id": parent_ids[j],
                            "child_frame_id": fid,
                            "translation": {"x": tr[j][0], "y": tr[j][1], "z": tr[j][2]},
                            "rotation": {"x": rq[j][0], "y": rq[j][1], "z": rq[j][2], "w": rq[j][3]},
                        }
                        for j, fid in enumerate(t.frame_ids)
                    ]
                }
                writer.add_message(tf_ch, log_time=t_ns, data=_json(msg), publish_time=t_ns, sequence=i)
                pos = positions[i].tolist()
                jmsg: dict[str, Any] = {
                    "timestamp": stamp,
                    "frame": i,
                    "frame_id": WORLD_FRAME,
                    "positions": {n: {"x": q[0], "y": q[1], "z": q[2]} for n, q in zip(t.names, pos)},
                }
                if t.confidence is not None:
                    jmsg["confidence"] = {n: c for n, c in zip(t.names, t.confidence[i].tolist())}
                writer.add_message(j_ch, log_time=t_ns, data=_json(jmsg), publish_time=t_ns, sequence=i)
                if poses:
                    wp = world_pos[i].tolist()
                    wr = world_rot[i].tolist()
                    pmsg = {
                        "timestamp": stamp,
                        "frame_id": WORLD_FRAME,
                        "poses": [
                            {
                                "position": {"x": a[0], "y": a[1], "z": a[2]},
                                "orientation": {"x": b[0], "y": b[1], "z": b[2], "w": b[3]},
                            }
                            for a, b in zip(wp, wr)
                        ],
                    }
                    writer.add_message(p_ch, log_time=t_ns, data=_json(pmsg), publish_time=t_ns, sequence=i)
        writer.finish()
    return p


def write_motion_mcap(
    motion: Motion,
    path: str | os.PathLike,
    *,
    topic_prefix: str = "/skeleton",
    poses: bool = False,
    start_time_ns: int = 0,
    compression: str = "zstd",
    units: str | None = None,
    up: str | None = None,
    **others: Any,
) -> Path:
    """Write a source :class:`Motion` as an MCAP recording (``physmocap convert x.bvh x.mcap``).

    See the module docstring for the layout; :func:`physmocap.sources.mcap.read_mcap`
    reads it back to the same motion (joint positions reproduced exactly).
    ``units`` and ``up`` are accepted only as ``"m"`` and ``"Z"``: MCAP
    recordings are always metres, Z-up (Foxglove's convention); the source
    file's own units and up axis are kept in the metadata.
    """
    if units not in (None, "m") or (up is not None and str(up).upper() != "Z"):
        raise OptionError(
            "MCAP recordings are always written in metres, Z-up (Foxglove's convention); "
            "drop --units / --up",
            path=path,
        )
    if others:
        raise OptionError(
            f"option(s) {sorted(others)} do not apply to MCAP output (rotations are quaternions, "
            "numbers are written exactly)",
            path=path,
        )
    track = track_from_motion(motion, topic_prefix=topic_prefix, role="source")
    return write_transforms_mcap(
        path, [track], motion.fps, start_time_ns=start_time_ns, poses=poses, compression=compression
    )


def _targets_track(targets: Any, prefix: str) -> TransformTrack | None:
    """The actor's canonical joints from retargeting targets, as a positional source track."""
    from ..canonical import canonical_parent

    names = tuple(getattr(targets, "names", ()) or ())
    pos = getattr(targets, "source_positions", None)
    if not names or pos is None:
        return None
    pos = np.asarray(pos, dtype=float)
    present = set(names)
    col = {n: k for k, n in enumerate(names)}
    parents = []
    for n in names:
        try:
            pc = canonical_parent(n, present)
        except KeyError:
            pc = None
        parents.append(-1 if pc is None else col[pc])
    if any(p >= k for k, p in enumerate(parents)):
        return None
    valid = getattr(targets, "valid", None)
    conf = None if valid is None else np.asarray(valid, dtype=float)
    track = track_from_world_poses(
        names, np.array(parents), np.where(np.isfinite(pos), pos, 0.0), None,
        topic_prefix=prefix, role="source", confidence=conf,
        metadata={"kind": "positional", "note": "the actor's canonical joints the character was fitted to"},
    )  # fmt: skip
    return track


def write_trajectory_mcap(
    traj: Any,
    path: str | os.PathLike,
    *,
    source: Motion | None = None,
    topic_prefix: str = "/character",
    source_prefix: str = "/source",
    poses: bool = False,
    compression: str = "zstd",
) -> Path:
    """Write a retargeted character (a :class:`physmocap.trajectory.Trajectory`) as MCAP.

    Every MuJoCo body except the world becomes a joint of the character track
    (parent: its parent body; bodies on the world are roots), from
    ``traj.body_poses()``.  The source plays beside it: ``source`` (a motion
    with the trajectory's frames) is written as its own track; without it,
    the actor's canonical joints the IK was given (``traj.targets``) are.
    """
    model = traj.model
    pos, quat = traj.body_poses()
    bodies = list(range(1, model.nbody))
    names = [model.body(b).name or f"body{b}" for b in bodies]
    index = {b: k for k, b in enumerate(bodies)}
    parents = [index.get(int(model.body_parentid[b]), -1) for b in bodies]
    track = track_from_world_poses(
        names,
        np.array(parents),
        pos[:, bodies],
        quat[:, bodies],
        topic_prefix=topic_prefix,
        role="character",
        metadata={"source": str(getattr(traj, "source", ""))},
    )
    tracks = [track]
    if source is not None:
        if source.num_frames != traj.num_frames:
            raise OutputError(
                f"the source has {source.num_frames} frames, the trajectory {traj.num_frames}", path=path
            )
        tracks.insert(0, track_from_motion(source, topic_prefix=source_prefix, role="source"))
    elif getattr(traj, "targets", None) is not None:
        st = _targets_track(traj.targets, source_prefix)
        if st is not None and st.num_frames == traj.num_frames:
            tracks.insert(0, st)
    return write_transforms_mcap(path, tracks, traj.fps, poses=poses, compression=compression)


def write_markers_mcap(rec: Any, path: str | os.PathLike, *, topic: str = "/markers", start_time_ns: int = 0,
                       compression: str = "zstd") -> Path:
    """Write a marker recording (:class:`~physmocap.markers.recording.MarkerRecording`) as
    MCAP, atomically: one ``physmocap.LabelledPoints`` message per frame on ``topic`` (the
    valid markers only, metres, the recording's own axes) and a ``physmocap.markers``
    metadata record (labels in order, fps, first frame, source).  Timestamps and bytes are a
    function of the input (:func:`frame_time_ns`); :func:`physmocap.sources.mcap.read_mcap_markers`
    reads it back exactly."""
    ok = np.all(np.isfinite(rec.positions), axis=2)

    def message(i: int) -> dict:
        return {"frame": i, "frame_id": WORLD_FRAME, "points": {
            lab: {"x": q[0], "y": q[1], "z": q[2]} for lab, q, v in zip(rec.labels, rec.positions[i].tolist(), ok[i]) if v}}

    return _write_marker_frames(rec, Path(path), topic, start_time_ns, compression, LABELLED_POINTS_SCHEMA, message)


def write_markers_pointcloud_mcap(rec: Any, path: str | os.PathLike, *, topic: str = "/markers",
                                  start_time_ns: int = 0, compression: str = "zstd") -> Path:
    """Write a marker recording as Foxglove ``foxglove.PointCloud`` messages (which Foxglove's
    3D panel draws), atomically: one cloud per frame on ``topic``, point ``k`` marker ``k``
    (x, y, z float64, metres, the recording's axes; NaN where unseen), and the labels, fps and
    first frame in a ``physmocap.markers`` metadata record, since a point cloud does not name
    its points.  Bytes are a function of the input; :func:`physmocap.sources.mcap.read_mcap_markers`
    reads it back exactly."""
    import base64

    fields = [{"name": axis, "offset": 8 * k, "type": _FLOAT64} for k, axis in enumerate("xyz")]
    pose = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
    points = np.ascontiguousarray(rec.positions, dtype="<f8")

    def message(i: int) -> dict:
        return {"frame_id": WORLD_FRAME, "pose": pose, "point_stride": 24, "fields": fields,
                "data": base64.b64encode(points[i].tobytes()).decode("ascii")}

    return _write_marker_frames(rec, Path(path), topic, start_time_ns, compression, POINT_CLOUD_SCHEMA, message)


def _write_marker_frames(rec: Any, p: Path, topic: str, start_time_ns: int, compression: str, schema: dict,
                         message: Any) -> Path:
    """The MCAP of :func:`write_markers_mcap` and :func:`write_markers_pointcloud_mcap`: the
    ``physmocap.markers`` metadata record, then ``message(i)`` (a dict) stamped with frame
    ``i``'s time on ``topic`` under ``schema``, for every frame."""
    from mcap.writer import CompressionType, Writer

    from ..resources import portable_path

    fps = float(rec.fps)
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}.get(compression)
    if comp is None:
        raise OutputError(f"compression must be zstd, lz4 or none, got {compression!r}", path=p)
    with atomic_open(p, "wb") as fh:
        writer = Writer(fh, compression=comp, enable_data_crcs=True)
        writer.start(profile="", library=LIBRARY)
        schema_id = writer.register_schema(schema["title"], "jsonschema", _schema_bytes(schema))
        ch = writer.register_channel(topic, "json", schema_id)
        writer.add_metadata(MARKERS_METADATA, {
            "labels": json.dumps(list(rec.labels)), "fps": repr(fps), "first_frame": str(int(rec.first_frame)),
            "topic": topic, "units": "m", "axes": "as recorded", "source": portable_path(str(rec.source), p.parent),
        })
        for i in range(rec.num_frames):
            t_ns = frame_time_ns(i, fps, start_time_ns)
            body = {"timestamp": _stamp(t_ns), **message(i)}
            writer.add_message(ch, log_time=t_ns, data=_json(body), publish_time=t_ns, sequence=i)
        writer.finish()
    return p
