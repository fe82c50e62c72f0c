"""Read skeleton recordings from MCAP files (Foxglove well-known schemas, JSON).

Three layouts are understood, tried in this order:

1. **physmocap's own** (written by :mod:`physmocap.export.mcap`): a
   ``physmocap.skeleton`` metadata record per skeleton (hierarchy, offsets,
   fps) with ``foxglove.FrameTransforms`` on ``<prefix>/tf`` and joint
   positions on ``<prefix>/joints``.  Reading gives back the motion that was
   written: rotational motions exactly (local rotations and translations),
   positional ones with their confidence.
2. **Any transform tree** in ``foxglove.FrameTransforms`` (or single
   ``foxglove.FrameTransform``) messages: every child frame becomes a joint,
   its parent frame its parent; frames whose parent is not itself a child
   frame (``world``, ``map``...) are the world.  A rotational motion.
3. **World joint poses** in ``foxglove.PosesInFrame``: one pose per joint,
   in a fixed joint order, one message per frame.  A positional motion (the
   poses' orientations are not used); joint names come from ``joint_names=``,
   a ``physmocap.skeleton`` record, the channel's ``joint_names`` metadata, or
   the known tracker layouts by count (15: NITE, 25: Kinect v2, 32: Azure Kinect).

Optical marker recordings (:func:`read_mcap_markers`; ``load_motion`` solves them like a C3D)
are a ``physmocap.LabelledPoints`` channel (written by ``physmocap convert take.c3d
take.mcap``: one message per frame, labelled points) or a ``foxglove.PointCloud`` channel
whose points are labelled by metadata (a point cloud names no point: the labels come from the
channel's ``labels`` metadata or a ``physmocap.markers`` metadata record, a JSON list in point
order, or indexed by an integer ``id`` field of the points; without them, one error).

Messages must be JSON-encoded (``message_encoding`` ``json``).  Frame ``i``
of a clip is the message stamped nearest ``t0 + i / fps``; fps comes from the
metadata, from ``fps=``, or from the median spacing of the timestamps.  A
frame with no message holds the previous one (positional recordings: it is a
lost frame and goes through the gap policy of :mod:`physmocap.sources.gaps`).

Foxglove's world is Z-up in metres like physmocap's, so nothing is converted
unless ``units=`` or ``up=`` say otherwise.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import InputError, OptionError, warn
from ..fileio import parse_json
from ..motion import MAX_JOINTS, Motion, Skeleton, forward_kinematics
from ..rotations import Rotation, quat_mul, up_axis_matrix
from . import check_grid

__all__ = ["read_mcap", "read_mcap_markers", "list_skeletons", "has_markers", "POINTCLOUD_SCHEMA"]

MAGIC = b"\x89MCAP0\r\n"
TF_SCHEMAS = ("foxglove.FrameTransforms", "foxglove.FrameTransform")
POSES_SCHEMA = "foxglove.PosesInFrame"
SKELETON_METADATA = "physmocap.skeleton"
MARKERS_SCHEMA = "physmocap.LabelledPoints"
MARKERS_METADATA = "physmocap.markers"
#: Latest timestamp accepted (ns since the clock's epoch, about 146 years): later ones are
#: corruption and would overflow 64-bit arithmetic.
MAX_STAMP_NS = 2**62


# --- raw records -------------------------------------------------------------------
@dataclass
class _Channel:
    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    metadata: dict[str, str]


@dataclass
class _Raw:
    channels: dict[int, _Channel] = field(default_factory=dict)
    messages: dict[int, list[tuple[int, bytes]]] = field(default_factory=dict)  # (log_time, data)
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)


def _load(path: Path) -> _Raw:
    """All channels, messages and metadata of an MCAP file, or one clear InputError."""
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(len(MAGIC))
            fh.seek(max(size - len(MAGIC), 0))
            tail = fh.read(len(MAGIC))
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", path=path) from None
    if head != MAGIC:
        raise InputError(
            "not an MCAP file: it does not start with the MCAP magic bytes (\\x89MCAP0\\r\\n)", path=path
        )
    if size < 2 * len(MAGIC) or tail != MAGIC:
        raise InputError(
            "truncated MCAP file: it does not end with the MCAP magic bytes (the recording "
            "was cut off before it was closed; `mcap recover` can salvage it)",
            path=path,
        )
    raw = _Raw()
    schemas: dict[int, Schema] = {}
    try:
        with open(path, "rb") as fh:
            for record in StreamReader(fh, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    sch = schemas.get(record.schema_id)
                    raw.channels[record.id] = _Channel(
                        id=record.id,
                        topic=record.topic,
                        encoding=record.message_encoding,
                        schema_name=sch.name if sch else "",
                        schema_encoding=sch.encoding if sch else "",
                        metadata=dict(record.metadata),
                    )
                elif isinstance(record, Message):
                    raw.messages.setdefault(record.channel_id, []).append((record.log_time, record.data))
                elif isinstance(record, Metadata):
                    raw.metadata.append((record.name, dict(record.metadata)))
    except Exception as exc:  # the mcap package raises many types on damaged input
        detail = str(exc) or type(exc).__name__
        raise InputError(f"corrupt MCAP file ({type(exc).__name__}: {detail})", path=path) from None
    for cid in raw.messages:
        if cid not in raw.channels:
            raise InputError(f"corrupt MCAP file: messages on undeclared channel {cid}", path=path)
    return raw


def _describe_channels(raw: _Raw) -> str:
    if not raw.channels:
        return "the file has no channels"
    parts = [
        f"{c.topic} ({c.schema_name or 'no schema'}, {c.encoding or 'no encoding'})"
        for c in sorted(raw.channels.values(), key=lambda c: c.id)
    ]
    return "channels: " + ", ".join(parts)


# --- JSON helpers -------------------------------------------------------------------
_NUMS = (int, float)  # exact types: bool is excluded


class _Decoder:
    """Decodes one channel's JSON messages with errors naming the message."""

    def __init__(self, path: Path, channel: _Channel) -> None:
        self.path = path
        self.channel = channel
        if channel.encoding != "json":
            raise InputError(
                f"topic {channel.topic} ({channel.schema_name}) uses {channel.encoding!r} message "
                "encoding; physmocap reads JSON-encoded Foxglove messages only",
                path=path,
            )

    def fail(self, k: int, what: str) -> InputError:
        return InputError(f"message {k} on {self.channel.topic}: {what}", path=self.path)

    def load(self, k: int, data: bytes) -> dict:
        try:
            obj = parse_json(data)
        except ValueError as exc:  # also UnicodeDecodeError
            raise self.fail(k, f"invalid JSON ({exc})") from None
        if not isinstance(obj, dict):
            raise self.fail(k, "expected a JSON object")
        return obj

    def number(self, k: int, obj: Any, key: str, default: float) -> float:
        v = obj.get(key, default) if isinstance(obj, dict) else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(k, f"field {key!r} must be a finite number, got {v!r}")
        return float(v)

    def vec3(self, k: int, obj: Any, key: str) -> list[float]:
        v = obj.get(key, {}) if isinstance(obj, dict) else None
        if type(v) is dict and len(v) == 3:  # fast path: x, y, z all plain finite numbers
            x, y, z = v.get("x"), v.get("y"), v.get("z")
            if type(x) in _NUMS and type(y) in _NUMS and type(z) in _NUMS and math.isfinite(x + y + z):
                return [float(x), float(y), float(z)]
        if not isinstance(v, dict):
            raise self.fail(k, f"field {key!r} must be an object with x, y, z")
        return [self.number(k, v, a, 0.0) for a in "xyz"]

    def quat(self, k: int, obj: Any, key: str) -> list[float]:
        v = obj.get(key)
        if v is None:
            return [0.0, 0.0, 0.0, 1.0]
        if not isinstance(v, dict):
            raise self.fail(k, f"field {key!r} must be an object with x, y, z, w")
        q = [v.get("x"), v.get("y"), v.get("z"), v.get("w")]
        if not (all(type(c) in _NUMS for c in q) and math.isfinite(sum(q))):  # type: ignore[arg-type]
            q = [self.number(k, v, a, 0.0) for a in "xyz"] + [self.number(k, v, "w", 1.0)]
        n = math.sqrt(sum(c * c for c in q))
        if not (1e-6 <= n < 1e150):  # inf or 0 would normalise to a zero quaternion
            raise self.fail(k, f"field {key!r} is not a rotation (quaternion norm {n:.3g})")
        if abs(n - 1.0) > 1e-9:
            q = [c / n for c in q]
        return q

    def stamp(self, k: int, obj: Any, log_time: int) -> int:
        """The message's time (ns): its ``timestamp``, else the record's log time; both
        within 0..:data:`MAX_STAMP_NS`."""
        ts = obj.get("timestamp") if isinstance(obj, dict) else None
        t = None
        if ts is None:
            pass
        elif type(ts) is dict and type(ts.get("sec")) is int and type(ts.get("nsec")) is int:
            if ts["sec"] >= 0 and ts["nsec"] >= 0:
                t = ts["sec"] * 1_000_000_000 + ts["nsec"]
        if t is None and ts is not None:
            if not isinstance(ts, dict):
                raise self.fail(k, "field 'timestamp' must be an object with sec and nsec")
            sec, nsec = ts.get("sec", 0), ts.get("nsec", 0)
            if not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in (sec, nsec)):
                raise self.fail(k, f"timestamp sec and nsec must be non-negative integers, got {sec!r}, {nsec!r}")
            t = sec * 1_000_000_000 + nsec
        if not t:
            t = log_time
        if not 0 <= t <= MAX_STAMP_NS:
            raise self.fail(k, f"timestamp {t / 1e9:.6g} s is out of range (0 to {MAX_STAMP_NS / 1e9:.3g} s)")
        return t


# --- frame grid -------------------------------------------------------------------
def _max_frames(distinct_times: int) -> int:
    """Most frames a clip with this many distinct timestamps may span (frames without a
    message hold the previous one; more than this is a wrong fps or a corrupt clock)."""
    return 4 * distinct_times + 10


def _frame_grid(
    path: Path, times: Sequence[int], fps: float | None, start: int | None
) -> tuple[np.ndarray, float, int]:
    """Frame index per timestamp, the fps and the number of frames."""
    from . import FPS_RANGE

    t = np.asarray(times, dtype=np.int64)  # each within 0..MAX_STAMP_NS (_Decoder.stamp)
    uniq = np.unique(t)
    if fps is None:
        if uniq.size < 2:
            raise InputError(
                "cannot tell the frame rate from a single timestamp; give fps=", path=path
            )
        fps = 1e9 / float(np.median(np.diff(uniq)))
        lo, hi = FPS_RANGE
        if not lo <= fps <= hi:
            raise InputError(
                f"the timestamps' median spacing gives {fps:.6g} fps, outside {lo:g}-{hi:g}; give fps=",
                path=path,
            )
    t0 = int(uniq[0]) if start is None else int(start)
    fidx = np.rint((t - t0) * (float(fps) / 1e9))  # float: no int64 overflow before the checks
    if fidx.min() < 0:
        raise InputError("messages stamped before the clip's start time", path=path)
    if fidx.max() + 1 > _max_frames(uniq.size):
        raise InputError(
            f"timestamps do not fit a {fps:.6g} fps clip ({uniq.size} distinct times would span "
            f"{fidx.max() + 1:.6g} frames); give the right fps=",
            path=path,
        )
    idx = fidx.astype(np.int64)
    return idx, float(fps), int(idx.max()) + 1


def _hold_fill(arr: np.ndarray, have: np.ndarray) -> np.ndarray:
    """Fill frames without data (``have`` False) with the previous frame's values
    (the next one's before the first), per joint.  ``arr (F, N, k)``, ``have (F, N)``."""
    F = arr.shape[0]
    out = arr.copy()
    idx = np.where(have, np.arange(F)[:, None], -1)
    last = np.maximum.accumulate(idx, axis=0)
    first = np.argmax(have, axis=0)
    last = np.where(last < 0, first[None, :], last)
    cols = np.arange(arr.shape[1])[None, :]
    return out[last, cols]


# --- transform trees --------------------------------------------------------------
@dataclass
class _TfData:
    frame_ids: list[str]
    parent_ids: list[str]
    translations: np.ndarray  # (F, N, 3)
    rotations: np.ndarray  # (F, N, 4)
    have: np.ndarray  # (F, N)
    fps: float


def _read_tf(
    path: Path,
    raw: _Raw,
    channels: list[_Channel],
    fps: float | None,
    start: int | None,
) -> _TfData:
    samples: list[tuple[int, str, str, list[float], list[float]]] = []
    for ch in channels:
        dec = _Decoder(path, ch)
        for k, (log_time, data) in enumerate(raw.messages.get(ch.id, [])):
            obj = dec.load(k, data)
            if ch.schema_name == "foxglove.FrameTransforms":
                items = obj.get("transforms", [])
                if not isinstance(items, list):
                    raise dec.fail(k, "field 'transforms' must be an array")
            else:
                items = [obj]
            msg_time = dec.stamp(k, obj, log_time) if ch.schema_name != "foxglove.FrameTransforms" else None
            for tr in items:
                if not isinstance(tr, dict):
                    raise dec.fail(k, "each transform must be an object")
                child, parent = tr.get("child_frame_id"), tr.get("parent_frame_id")
                if not isinstance(child, str) or not child or not isinstance(parent, str):
                    raise dec.fail(k, "a transform needs string parent_frame_id and child_frame_id")
                when = msg_time if msg_time is not None else dec.stamp(k, tr, log_time)
                samples.append((when, child, parent, dec.vec3(k, tr, "translation"), dec.quat(k, tr, "rotation")))
    if not samples:
        raise InputError("the transform topics hold no messages", path=path)

    parent_of: dict[str, str] = {}
    order: list[str] = []
    for _, child, parent, _, _ in samples:
        if child not in parent_of:
            parent_of[child] = parent
            order.append(child)
        elif parent_of[child] != parent:
            raise InputError(
                f"frame {child!r} changes parent from {parent_of[child]!r} to {parent!r}; "
                "physmocap needs a fixed hierarchy",
                path=path,
            )
    # parents before children: walk from the roots (parents that are not children)
    children: dict[str, list[str]] = {}
    for c in order:
        children.setdefault(parent_of[c], []).append(c)
    sorted_ids: list[str] = []
    stack = [c for c in order if parent_of[c] not in parent_of][::-1]
    while stack:
        c = stack.pop()
        sorted_ids.append(c)
        stack.extend(children.get(c, [])[::-1])
    if len(sorted_ids) != len(order):
        cyclic = sorted(set(order) - set(sorted_ids))
        raise InputError(f"the transform tree has a cycle through {cyclic}", path=path)
    col = {c: i for i, c in enumerate(sorted_ids)}

    idx, fps, F = _frame_grid(path, [s[0] for s in samples], fps, start)
    N = len(sorted_ids)
    check_grid(path, F, N, len(samples))
    trans = np.zeros((F, N, 3))
    rots = np.zeros((F, N, 4))
    rots[..., 3] = 1.0
    have = np.zeros((F, N), dtype=bool)
    for i, (_, child, _, t, q) in zip(idx, samples):
        j = col[child]
        trans[i, j] = t
        rots[i, j] = q
        have[i, j] = True
    if not have.all():
        missing = int((~have).sum())
        warn(f"{path}: {missing} joint transform(s) missing over {F} frames; holding the previous ones")
        trans = _hold_fill(trans, have)
        rots = _hold_fill(rots, have)
    parents = [parent_of[c] for c in sorted_ids]
    return _TfData(sorted_ids, parents, trans, rots, have, fps)


def _convert_rotational(
    trans: np.ndarray, rots: np.ndarray, scale: float, up: str
) -> tuple[np.ndarray, np.ndarray]:
    """Scale translations to metres and turn a Y-up world to Z-up (``R' = M R M^T``)."""
    trans = trans * scale
    if up.upper() != "Z":
        M = up_axis_matrix(up, "Z")
        qm = Rotation.from_matrix(M).as_quat()
        qm_inv = qm * np.array([-1.0, -1.0, -1.0, 1.0])
        trans = trans @ M.T
        rots = quat_mul(quat_mul(qm, rots), qm_inv)
    return trans, rots


# --- metadata tracks ----------------------------------------------------------------
_REQUIRED = object()


class _Meta:
    """Typed, range-checked fields of one ``physmocap.skeleton`` metadata record (every value
    is a JSON text); errors name the file, the skeleton and the field."""

    def __init__(self, path: Path, meta: dict[str, str]) -> None:
        self.path = path
        self.meta = meta
        prefix = meta.get("topic_prefix", "/skeleton")
        self.prefix = prefix if len(prefix) <= 200 else prefix[:200] + "..."

    def fail(self, key: str, what: str) -> InputError:
        return InputError(f"skeleton {self.prefix}: physmocap.skeleton metadata {key!r} {what}", path=self.path)

    def json(self, key: str, default: Any = _REQUIRED) -> Any:
        if key not in self.meta:
            if default is _REQUIRED:
                raise self.fail(key, "is missing")
            return default
        try:
            return parse_json(self.meta[key])
        except ValueError as exc:
            raise self.fail(key, f"is not valid JSON ({exc})") from None

    def number(self, key: str, lo: float, hi: float, integer: bool = False, default: Any = _REQUIRED) -> float:
        v = self.json(key, default)
        if isinstance(v, str):  # physmocap writes numbers as JSON text; tolerate a quoted one
            try:
                v = parse_json(v)
            except ValueError:
                pass
        kind = "an integer" if integer else "a number"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
            raise self.fail(key, f"must be {kind}, got {str(v)[:40]!r}")
        if not (math.isfinite(v) and lo <= v <= hi):
            raise self.fail(key, f"is {v:.6g}; expected {kind} from {lo:g} to {hi:g}")
        return v

    def items(self, key: str, kind: str, count: int | None = None, default: Any = _REQUIRED) -> list:
        """A JSON list of ``count`` items of ``kind``: "str", "int", "bool" or "vec3"."""
        v = self.json(key, default)
        checks = {
            "str": lambda x: isinstance(x, str),
            "int": lambda x: isinstance(x, int) and not isinstance(x, bool),
            "bool": lambda x: isinstance(x, bool),
            "vec3": lambda x: isinstance(x, list) and len(x) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in x),
        }
        names = {"str": "strings", "int": "integers", "bool": "true/false values", "vec3": "[x, y, z] finite numbers"}
        size = f"{count} " if count is not None else ""
        if not isinstance(v, list) or (count is not None and len(v) != count):
            got = f"{len(v)} items" if isinstance(v, list) else type(v).__name__
            raise self.fail(key, f"must be a list of {size}{names[kind]}, got {got}")
        for i, x in enumerate(v):
            if not checks[kind](x):
                one = {"str": "a string", "int": "an integer", "bool": "true or false", "vec3": "[x, y, z] finite numbers"}
                raise self.fail(key, f"item {i} must be {one[kind]}, got {str(x)[:40]!r}")
        return v


def _is_str_list(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


#: The source motion's ``meta`` entries physmocap acts on, each with the check its value must
#: pass in a file (a wrong type would fail far from the file); other entries are kept as read.
_SOURCE_META_CHECKS: dict[str, Any] = {
    "format": lambda v: isinstance(v, str),
    "units_detected": lambda v: isinstance(v, bool),
    "floor_z": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) < 1000.0,
    "bvh_channels": lambda v: isinstance(v, dict) and all(_is_str_list(c) for c in v.values()),
    "bvh_rotation_orders": lambda v: isinstance(v, dict) and all(isinstance(o, str) for o in v.values()),
    "source_mapping": lambda v: isinstance(v, dict),
}


def _source_meta(m: _Meta, value: Any) -> dict:
    """The checked ``meta`` of a physmocap.skeleton record (see :data:`_SOURCE_META_CHECKS`)."""
    from ..fileio import MAX_NESTING, json_depth

    if not isinstance(value, dict):
        raise m.fail("meta", f"must be a JSON object, got {type(value).__name__}")
    if json_depth(value) > MAX_NESTING:
        raise m.fail("meta", f"is nested deeper than {MAX_NESTING} levels")
    out = dict(value)
    for key, check in _SOURCE_META_CHECKS.items():
        if key in out and not check(out[key]):
            raise m.fail("meta", f"entry {key!r} has the wrong type or range: {str(out[key])[:60]}")
    if "source_mapping" in out:
        from ..errors import MappingError
        from .profiles.mapfile import check_mapping

        try:
            check_mapping(out["source_mapping"])
        except MappingError as exc:
            raise m.fail("meta", f"entry 'source_mapping' is not a mapping ({exc.message})") from None
    return out


def list_skeletons(path: str | os.PathLike) -> list[dict[str, str]]:
    """The ``physmocap.skeleton`` metadata records of a file (one per skeleton)."""
    raw = _load(Path(path))
    return [m for name, m in raw.metadata if name == SKELETON_METADATA]


def _pick_track(path: Path, tracks: list[dict[str, str]], skeleton: str | None) -> dict[str, str]:
    if skeleton is not None:
        want = "/" + skeleton.strip("/")
        for t in tracks:
            if t.get("topic_prefix") == want or t.get("role") == skeleton:
                return t
        known = ", ".join(f"{t.get('topic_prefix')} ({t.get('role')})" for t in tracks)
        raise OptionError(f"no skeleton {skeleton!r} in the file; it has {known}", path=path)
    for t in tracks:
        if t.get("role") == "source":
            return t
    return tracks[0]


def _read_own(path: Path, raw: _Raw, meta: dict[str, str], options: dict[str, Any]) -> Motion:
    prefix = meta.get("topic_prefix", "/skeleton")
    if meta.get("units", "m") != "m" or meta.get("up_axis", "Z").upper() != "Z":
        raise InputError(
            f"skeleton {prefix}: units {meta.get('units')!r} / up axis {meta.get('up_axis')!r} are "
            "not supported (physmocap writes metres, Z-up)",
            path=path,
        )
    from . import FPS_RANGE

    m = _Meta(path, meta)
    prefix = m.prefix
    names = m.items("joints", "str")
    N = len(names)
    if not 1 <= N <= MAX_JOINTS:
        raise m.fail("joints", f"lists {N} joints; expected 1 to {MAX_JOINTS}")
    frame_ids = m.items("frame_ids", "str", N)
    parent_list = m.items("parents", "int", N)
    for j, pj in enumerate(parent_list):
        if not -1 <= pj < j:
            raise m.fail("parents", f"item {j} is {pj}; a parent is -1 or an earlier joint's index (0 to {j - 1})")
    parents = np.asarray(parent_list, dtype=np.int64)
    fps = float(m.number("fps", *FPS_RANGE))
    start = int(m.number("start_time_ns", 0, MAX_STAMP_NS, integer=True, default=0))
    kind = meta.get("kind", "rotational")
    if kind not in ("rotational", "positional"):
        raise m.fail("kind", f"is {kind[:40]!r}; expected rotational or positional")
    file_up = meta.get("source_file_up", "Z")
    if file_up.upper() not in ("X", "Y", "Z"):
        raise m.fail("source_file_up", f"is {file_up[:40]!r}; expected X, Y or Z")
    topics = {c.topic: c for c in raw.channels.values()}
    tf_ch = topics.get(f"{prefix}/tf")
    if tf_ch is None or tf_ch.schema_name not in TF_SCHEMAS:
        raise InputError(f"skeleton {prefix}: no foxglove.FrameTransforms channel {prefix}/tf", path=path)
    n_msgs = len(raw.messages.get(tf_ch.id, []))
    F = int(m.number("num_frames", 1, max(1, _max_frames(n_msgs)), integer=True))
    tf = _read_tf(path, raw, [tf_ch], fps, start)
    col = {fid: i for i, fid in enumerate(tf.frame_ids)}
    missing = [f for f in frame_ids if f not in col]
    if missing:
        raise InputError(f"skeleton {prefix}: no transforms for frames {missing[:5]}", path=path)
    sel = np.array([col[f] for f in frame_ids])
    if tf.translations.shape[0] != F:
        if tf.translations.shape[0] > F:
            raise InputError(f"skeleton {prefix}: transforms stamped past its {F} frames", path=path)
        pad = F - tf.translations.shape[0]
        tf.translations = np.concatenate([tf.translations, np.repeat(tf.translations[-1:], pad, 0)])
        tf.rotations = np.concatenate([tf.rotations, np.repeat(tf.rotations[-1:], pad, 0)])
        warn(f"{path}: skeleton {prefix} has transforms for {F - pad} of {F} frames; holding the last")
    trans = tf.translations[:, sel]
    rots = tf.rotations[:, sel]
    for j, p in enumerate(parents):
        expect = frame_ids[p] if p >= 0 else None
        got = tf.parent_ids[sel[j]]
        if expect is not None and got != expect:
            raise InputError(
                f"skeleton {prefix}: transform of {frame_ids[j]!r} has parent {got!r}, metadata says {expect!r}",
                path=path,
            )
    offsets = np.asarray(m.items("offsets", "vec3", N, default=trans[0].tolist()), dtype=float)
    end_site = np.asarray(m.items("end_site", "bool", N, default=[False] * N), dtype=bool)
    try:
        skeleton = Skeleton(names=tuple(names), parents=parents, offsets=offsets, end_site=end_site)
    except ValueError as exc:
        raise InputError(f"skeleton {prefix}: {exc}", path=path) from None
    source_meta = _source_meta(m, m.json("meta", default={}))
    unit_scale = float(m.number("source_unit_scale", 1e-9, 1e9, default=1.0))
    common: dict[str, Any] = dict(
        skeleton=skeleton,
        fps=fps,
        source=str(path),
        units=meta.get("source_units", "m"),
        unit_scale=unit_scale,
        file_up=file_up.upper(),
        meta={**source_meta, "mcap": {"topic_prefix": prefix}},
    )
    if kind == "positional":
        positions, confidence = _read_joint_positions(path, raw, topics.get(f"{prefix}/joints"), names, fps, start, F)
        if positions is None:
            positions, _ = forward_kinematics(skeleton, rots, trans, np.arange(N))
        return Motion(positions=positions, confidence=confidence, **common)
    if "translated" in meta:
        translated = np.asarray(m.items("translated", "int"), dtype=np.int64)
        if translated.size and (translated.min() < 0 or translated.max() >= N or np.any(np.diff(translated) <= 0)):
            raise m.fail("translated", f"must list joint indices (0 to {N - 1}) in increasing order")
    else:
        translated = np.flatnonzero(np.any(np.abs(trans - offsets) > 1e-12, axis=(0, 2)))
    return Motion(rotations=rots, translations=trans[:, translated], translated=translated, **common)


def _read_joint_positions(
    path: Path,
    raw: _Raw,
    ch: _Channel | None,
    names: list[str],
    fps: float,
    start: int,
    F: int,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    if ch is None or not raw.messages.get(ch.id):
        return None, None
    dec = _Decoder(path, ch)
    pos = np.full((F, len(names), 3), np.nan)
    conf = np.zeros((F, len(names)))
    any_conf = False
    col = {n: i for i, n in enumerate(names)}
    for k, (log_time, data) in enumerate(raw.messages[ch.id]):
        obj = dec.load(k, data)
        t = dec.stamp(k, obj, log_time)
        i = int(round((t - start) * fps / 1e9))
        if not 0 <= i < F:
            raise dec.fail(k, f"stamped outside the clip's {F} frames")
        p = obj.get("positions")
        if not isinstance(p, dict):
            raise dec.fail(k, "field 'positions' must be an object of joint name -> {x, y, z}")
        for name, v in p.items():
            if name in col:
                pos[i, col[name]] = dec.vec3(k, p, name)
        c = obj.get("confidence")
        if isinstance(c, dict):
            any_conf = True
            for name in c:
                if name in col:
                    conf[i, col[name]] = min(max(dec.number(k, c, name, 0.0), 0.0), 1.0)
    if not np.all(np.isfinite(pos)):
        return None, None
    return pos, (conf if any_conf else None)


# --- PosesInFrame -----------------------------------------------------------------
def _read_poses(
    path: Path,
    raw: _Raw,
    ch: _Channel,
    joint_names: Sequence[str] | None,
    fps: float | None,
    options: dict[str, Any],
) -> Motion:
    from .positions import known_layout, positional_motion

    dec = _Decoder(path, ch)
    frames: list[tuple[int, list[list[float]]]] = []
    for k, (log_time, data) in enumerate(raw.messages.get(ch.id, [])):
        obj = dec.load(k, data)
        poses = obj.get("poses", [])
        if not isinstance(poses, list):
            raise dec.fail(k, "field 'poses' must be an array")
        pts = []
        for pose in poses:
            if not isinstance(pose, dict):
                raise dec.fail(k, "each pose must be an object")
            pts.append(dec.vec3(k, pose, "position"))
        frames.append((dec.stamp(k, obj, log_time), pts))
    if not frames:
        raise InputError(f"topic {ch.topic} holds no messages", path=path)
    J = max(len(p) for _, p in frames)
    if J == 0:
        raise InputError(f"topic {ch.topic}: every message has an empty poses array", path=path)
    names: list[str] | None = None
    if joint_names is not None:
        names = [str(n) for n in joint_names]
    elif "joint_names" in ch.metadata:
        try:
            listed = parse_json(ch.metadata["joint_names"])
        except ValueError:
            listed = None
        if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
            raise InputError(f"channel {ch.topic}: metadata joint_names is not a JSON list of names", path=path)
        names = listed
    else:
        for name, meta in raw.metadata:
            if name != SKELETON_METADATA:
                continue
            m = _Meta(path, meta)
            topics = m.json("topics", default={})
            if isinstance(topics, dict) and topics.get("poses") == ch.topic:
                names = m.items("joints", "str")
        if names is None:
            names = known_layout(J)
    if names is None:
        names = [f"joint_{k}" for k in range(J)]
        warn(f"{path}: {ch.topic} has {J} poses per frame and no joint names; calling them joint_0..")
    if len(names) != J:
        raise InputError(f"topic {ch.topic}: {J} poses per frame but {len(names)} joint names", path=path)
    idx, fps, F = _frame_grid(path, [t for t, _ in frames], fps, None)
    check_grid(path, F, J, sum(len(p) for _, p in frames))
    pos = np.full((F, J, 3), np.nan)
    for i, (_, pts) in zip(idx, frames):
        if len(pts) == J:
            pos[i] = pts
        elif pts:
            raise InputError(
                f"topic {ch.topic}: frame {int(i)} has {len(pts)} poses, others have {J}", path=path, frame=int(i)
            )
    opts = {"frame": "world", "up": "Z", "units": "m", "level": False, "floor": None}
    opts.update(options)
    return positional_motion(names, pos, None, fps, path, **opts)


# --- entry point -------------------------------------------------------------------
def read_mcap(
    path: str | os.PathLike,
    *,
    skeleton: str | None = None,
    topic: str | None = None,
    joint_names: Sequence[str] | None = None,
    fps: float | None = None,
    units: str | float | None = None,
    up: str | None = None,
    **options: Any,
) -> Motion:
    """Read a skeleton recording from an MCAP file (layouts: module docstring).

    Args:
        path: The ``.mcap`` file.
        skeleton: Which physmocap skeleton (topic prefix such as ``/skeleton``,
            or role ``source`` / ``character``); default: the source.
        topic: For foreign recordings, the topic to read (default: the first
            FrameTransforms topic, else the first PosesInFrame topic).
        joint_names: Joint order of PosesInFrame poses.
        fps: Frame rate, when the file does not say.
        units: For foreign recordings: the length unit (default metres).
        up: For foreign recordings: the world's up axis, ``"Z"`` (default) or ``"Y"``.
        **options: Passed to the positional pipeline for PosesInFrame
            recordings (:func:`physmocap.sources.positions.positional_motion`); for a marker
            recording, to :func:`physmocap.markers.motion.marker_motion` (the solved actor by
            default, the joint centres with ``solve=False``).

    Raises:
        InputError: not an MCAP file, truncated or corrupt, no skeleton
            data, unknown schemas or encodings, malformed messages.
    """
    p = Path(path)
    raw = _load(p)
    tracks = [m for name, m in raw.metadata if name == SKELETON_METADATA]
    if topic is None and _is_marker_recording(raw):
        from ..markers.motion import marker_motion

        return marker_motion(_markers(p, raw, units), **options)
    if tracks and topic is None:
        if (units is not None and str(units).lower() not in ("m", "auto")) or (up is not None and up.upper() != "Z"):
            raise OptionError(
                "this recording was written by physmocap and says its own units and up axis "
                "(metres, Z-up); drop the units / up override",
                path=p,
            )
        return _read_own(p, raw, _pick_track(p, tracks, skeleton), options)

    chans = sorted(raw.channels.values(), key=lambda c: c.id)
    if topic is not None:
        chans = [c for c in chans if c.topic == topic]
        if not chans:
            raise OptionError(f"no topic {topic!r}; {_describe_channels(raw)}", path=p)
    tf_chans = [c for c in chans if c.schema_name in TF_SCHEMAS]
    pose_chans = [c for c in chans if c.schema_name == POSES_SCHEMA]
    if tf_chans:
        tf = _read_tf(p, raw, tf_chans, fps, None)
        from .sensor import unit_scale

        scale = unit_scale(units, p)[1] if units is not None else 1.0
        trans, rots = _convert_rotational(tf.translations, tf.rotations, scale, up or "Z")
        names = tf.frame_ids
        col = {c: i for i, c in enumerate(names)}
        parents = np.array([col.get(pp, -1) for pp in tf.parent_ids], dtype=np.int64)
        offsets = trans[0]
        skel = Skeleton(names=tuple(names), parents=parents, offsets=offsets)
        translated = np.flatnonzero(np.any(np.abs(trans - offsets) > 1e-12, axis=(0, 2)))
        return Motion(
            skeleton=skel,
            fps=tf.fps,
            rotations=rots,
            translations=trans[:, translated],
            translated=translated,
            source=str(p),
            units="m" if units is None else str(units),
            unit_scale=scale,
            file_up=(up or "Z").upper(),
            meta={"mcap": {"topics": [c.topic for c in tf_chans], "world_frames": sorted(
                {pp for pp in tf.parent_ids if pp not in col})}},
        )
    if pose_chans:
        if len(pose_chans) > 1:
            warn(f"{p}: several PosesInFrame topics; reading {pose_chans[0].topic} (choose with topic=)")
        opts = dict(options)
        if units is not None:
            opts["units"] = units
        if up is not None:
            opts["up"] = up
        return _read_poses(p, raw, pose_chans[0], joint_names, fps, opts)
    raise InputError(
        "no skeleton data: physmocap reads foxglove.FrameTransforms, foxglove.FrameTransform or "
        f"foxglove.PosesInFrame messages in JSON encoding; {_describe_channels(raw)}",
        path=p,
    )


# --- optical markers ---------------------------------------------------------------
#: Foxglove's point cloud schema: packed little-endian points, no labels (see :func:`_cloud_labels`).
POINTCLOUD_SCHEMA = "foxglove.PointCloud"
#: Foxglove ``NumericType`` -> NumPy dtype (integers little-endian, as Foxglove specifies).
NUMERIC_TYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<f4", 8: "<f8"}


def _skeleton_channels(raw: _Raw) -> bool:
    return any(c.schema_name in TF_SCHEMAS or c.schema_name == POSES_SCHEMA for c in raw.channels.values())


def _marker_channel(raw: _Raw) -> _Channel | None:
    """The marker channel: the first ``physmocap.LabelledPoints`` one; else the first
    ``foxglove.PointCloud`` one whose points have labels (:func:`_cloud_labels`); else the
    first point cloud of a file with no skeleton channel (whose reading then says what is
    missing).  A point cloud beside a transform tree without labels is not taken for markers
    (a depth camera's, a lidar's)."""
    chans = sorted(raw.channels.values(), key=lambda c: c.id)
    own = [c for c in chans if c.schema_name == MARKERS_SCHEMA]
    if own:
        return own[0]
    clouds = [c for c in chans if c.schema_name == POINTCLOUD_SCHEMA]
    labelled = [c for c in clouds if _marker_meta(raw, c).get("labels") or c.metadata.get("labels")]
    if labelled:
        return labelled[0]
    return clouds[0] if clouds and not _skeleton_channels(raw) else None


def _is_marker_recording(raw: _Raw) -> bool:
    """Whether :func:`read_mcap` reads ``raw`` as markers: no physmocap skeleton track and a
    marker channel (:func:`_marker_channel`)."""
    has_track = any(name == SKELETON_METADATA for name, _ in raw.metadata)
    return not has_track and _marker_channel(raw) is not None


def has_markers(path: str | os.PathLike) -> bool:
    """Whether an MCAP file is a marker recording (``physmocap.LabelledPoints``, or a
    ``foxglove.PointCloud`` that is taken for markers: :func:`_marker_channel`), read as
    markers by :func:`read_mcap`, not a skeleton recording."""
    return _is_marker_recording(_load(Path(path)))


def read_mcap_markers(path: str | os.PathLike, units: str | float | None = None):
    """The marker recording (:class:`~physmocap.markers.recording.MarkerRecording`) of an MCAP
    file: a ``physmocap.LabelledPoints`` channel (written by
    :func:`physmocap.export.mcap.write_markers_mcap`; frame ``i`` is the message with
    ``"frame": i``, markers absent from a message are gaps) or a labelled
    ``foxglove.PointCloud`` channel (:func:`_cloud_markers`)."""
    p = Path(path)
    return _markers(p, _load(p), units)


def _marker_meta(raw: _Raw, ch: _Channel) -> dict[str, str]:
    """The ``physmocap.markers`` metadata record for ``ch`` (one naming its topic, or naming none)."""
    return next((m for name, m in raw.metadata if name == MARKERS_METADATA and m.get("topic", ch.topic) == ch.topic), {})


def _json_labels(p: Path, text: str, where: str) -> list[str]:
    """Marker labels from a JSON list of strings (a metadata value), or one InputError naming ``where``."""
    try:
        labels = parse_json(text)
    except ValueError:
        labels = None
    if not isinstance(labels, list) or not all(isinstance(x, str) and x.strip() for x in labels):
        raise InputError(f"{where}: labels must be a JSON list of non-empty strings", path=p)
    return [str(x) for x in labels]


def _markers(p: Path, raw: _Raw, units: str | float | None):
    from ..markers.recording import MarkerRecording, unique_labels, unit_scale

    ch = _marker_channel(raw)
    if ch is None:
        raise InputError(f"no marker channel (physmocap.LabelledPoints, or foxglove.PointCloud with labels); "
                         f"{_describe_channels(raw)}", path=p)
    msgs = raw.messages.get(ch.id, [])
    if not msgs:
        raise InputError(f"no messages on {ch.topic}", path=p)
    meta = _marker_meta(raw, ch)
    read = _cloud_markers if ch.schema_name == POINTCLOUD_SCHEMA else _labelled_points
    labels, P, times, fps = read(p, raw, ch, meta)
    if fps is None:
        try:
            fps = float(meta.get("fps", ch.metadata.get("fps", "nan")))
        except ValueError:
            fps = float("nan")
    if not (math.isfinite(fps) and fps > 0):
        dt = np.diff(np.unique(times))
        if not dt.size:
            raise InputError("cannot tell the frame rate: one timestamp and no fps metadata", path=p)
        fps = 1e9 / float(np.median(dt))
    scale = unit_scale(units, p) if units is not None else 1.0
    first = int(meta.get("first_frame", "0")) if str(meta.get("first_frame", "0")).isdigit() else 0
    labels = unique_labels(labels, f"{p}: the labels of {ch.topic}")
    return MarkerRecording(labels=tuple(labels), positions=P * scale, fps=fps, source=p, first_frame=first)


def _labelled_points(p: Path, raw: _Raw, ch: _Channel, meta: dict[str, str]):
    """``(labels, (F, M, 3) positions, timestamps, None)`` of a ``physmocap.LabelledPoints``
    channel: frame ``i`` is the message with ``"frame": i``; a frame number held by two
    messages is an error naming both."""
    dec = _Decoder(p, ch)
    labels = _json_labels(p, meta["labels"], "the physmocap.markers metadata") if "labels" in meta else []
    seen = set(labels)
    frames: list[tuple[int, dict]] = []
    times = []
    first_msg: dict[int, int] = {}
    for k, (log_time, data) in enumerate(raw.messages[ch.id]):
        obj = dec.load(k, data)
        f = obj.get("frame")
        if isinstance(f, bool) or not isinstance(f, int) or f < 0:
            raise dec.fail(k, f"field 'frame' must be a non-negative integer, got {f!r}")
        if f in first_msg:
            raise dec.fail(k, f"frame {f} again (message {first_msg[f]} holds it too): which one is the frame "
                           "cannot be told")
        first_msg[f] = k
        pts = obj.get("points")
        if not isinstance(pts, dict):
            raise dec.fail(k, "field 'points' must be an object of label -> {x, y, z}")
        for lab in pts:
            if lab not in seen:
                seen.add(lab)
                labels.append(lab)
        frames.append((f, pts))
        times.append(dec.stamp(k, obj, log_time))
    F = max(f for f, _ in frames) + 1
    check_grid(p, F, len(labels), sum(len(pts) for _, pts in frames))
    col = {lab: j for j, lab in enumerate(labels)}
    P = np.full((F, len(labels), 3), np.nan)
    for k, (f, pts) in enumerate(frames):
        for lab, v in pts.items():
            P[f, col[lab]] = dec.vec3(k, pts, lab)
    return labels, P, times, None


def _cloud_labels(p: Path, ch: _Channel, meta: dict[str, str]) -> list[str]:
    """The marker labels of a ``foxglove.PointCloud`` channel, which has none of its own: the
    channel's ``labels`` metadata, else the ``labels`` of a ``physmocap.markers`` metadata
    record naming the topic (a JSON list: point ``k`` of every message, or the point whose
    ``id`` field is ``k``, is marker ``labels[k]``)."""
    if "labels" in ch.metadata:
        return _json_labels(p, ch.metadata["labels"], f"the metadata of channel {ch.topic}")
    if "labels" in meta:
        return _json_labels(p, meta["labels"], "the physmocap.markers metadata")
    raise InputError(
        f"{ch.topic} is a foxglove.PointCloud without marker labels: a point cloud does not name its points, so "
        "the markers cannot be told apart (physmocap does not label markers). Give the labels, in point order, "
        "as a JSON list in the channel's 'labels' metadata or in a physmocap.markers metadata record "
        f"{{\"topic\": \"{ch.topic}\", \"labels\": \"[...]\"}}", path=p)


def _cloud_fields(dec: _Decoder, k: int, obj: dict) -> tuple[int, dict[str, tuple[int, str]]]:
    """``(point_stride, name -> (offset, dtype))`` of one PointCloud message, checked."""
    stride = obj.get("point_stride")
    if isinstance(stride, bool) or not isinstance(stride, int) or stride <= 0:
        raise dec.fail(k, f"field 'point_stride' must be a positive integer, got {stride!r}")
    fields = obj.get("fields")
    if not isinstance(fields, list):
        raise dec.fail(k, "field 'fields' must be a list of {name, offset, type}")
    out: dict[str, tuple[int, str]] = {}
    for f in fields:
        name, off, typ = (f.get("name"), f.get("offset"), f.get("type")) if isinstance(f, dict) else (None, None, None)
        if not isinstance(name, str) or isinstance(off, bool) or not isinstance(off, int) or off < 0:
            raise dec.fail(k, f"a packed field needs a name and a non-negative offset, got {f!r}")
        dtype = NUMERIC_TYPES.get(typ) if isinstance(typ, int) and not isinstance(typ, bool) else None
        if dtype is None:
            raise dec.fail(k, f"field {name!r}: numeric type {typ!r} is not one of Foxglove's 1-8 (UINT8 to FLOAT64)")
        if off + np.dtype(dtype).itemsize > stride:
            raise dec.fail(k, f"field {name!r} (offset {off}, {np.dtype(dtype).itemsize} bytes) runs past the "
                           f"point stride of {stride} bytes")
        out[name] = (off, dtype)
    missing = [a for a in "xyz" if a not in out]
    if missing:
        raise dec.fail(k, f"the points have no {', '.join(missing)} field: markers need x, y and z")
    return stride, out


def _cloud_points(dec: _Decoder, k: int, obj: dict) -> tuple[np.ndarray, np.ndarray | None]:
    """``(N, 3)`` points of one PointCloud message in its frame (its ``pose`` applied; NaN
    or all-zero points, the usual "not seen", as NaN) and the ``(N,)`` ``id`` field if any."""
    import base64
    import binascii

    stride, fields = _cloud_fields(dec, k, obj)
    data = obj.get("data", "")
    try:
        buf = base64.b64decode(data, validate=True) if isinstance(data, str) else None
    except (binascii.Error, ValueError):
        buf = None
    if buf is None:
        raise dec.fail(k, "field 'data' must be the points' bytes in base64 (Foxglove's JSON encoding of bytes)")
    if len(buf) % stride:
        raise dec.fail(k, f"{len(buf)} bytes of point data are not a whole number of {stride}-byte points")
    n = len(buf) // stride
    raw = np.frombuffer(buf, dtype=np.uint8).reshape(n, stride)

    def column(name: str) -> np.ndarray:
        off, dtype = fields[name]
        size = np.dtype(dtype).itemsize
        return raw[:, off:off + size].copy().view(dtype).reshape(n).astype(float)

    X = np.stack([column(a) for a in "xyz"], 1)
    X[np.all(X == 0.0, axis=1) | ~np.all(np.isfinite(X), axis=1)] = np.nan
    pose = obj.get("pose")
    if pose is not None:
        if not isinstance(pose, dict):
            raise dec.fail(k, "field 'pose' must be an object with position and orientation")
        t = np.array(dec.vec3(k, pose, "position"))
        x, y, z, w = dec.quat(k, pose, "orientation")
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        X = X @ R.T + t
    ids = column("id") if "id" in fields else None
    return X, ids


def _cloud_markers(p: Path, raw: _Raw, ch: _Channel, meta: dict[str, str]):
    """``(labels, (F, M, 3) positions, timestamps, fps)`` of a ``foxglove.PointCloud``
    channel (JSON encoding: ``data`` base64, ``fields`` with Foxglove ``NumericType``s).

    Labels: :func:`_cloud_labels`.  Point ``k`` of a message is marker ``labels[k]`` (every
    message then holds one point per label, NaN or all-zero where unseen), or, when the points
    have an integer ``id`` field, marker ``labels[id]`` (unseen markers may be left out).
    Frame ``i`` is the message stamped ``t0 + i / fps`` (fps from the metadata's ``fps``, else
    the timestamps' spacing); two messages with the same timestamp, or in different
    ``frame_id``s, are an error naming them.
    """
    dec = _Decoder(p, ch)
    labels = _cloud_labels(p, ch, meta)
    M = len(labels)
    clouds: list[np.ndarray] = []
    times: list[int] = []
    frame_ids: dict[str, int] = {}
    stamped: dict[int, int] = {}
    for k, (log_time, data) in enumerate(raw.messages[ch.id]):
        obj = dec.load(k, data)
        t = dec.stamp(k, obj, log_time)
        if t in stamped:
            raise dec.fail(k, f"timestamp {t / 1e9:.9f} s again (message {stamped[t]} has it too): two clouds "
                           "for one frame")
        stamped[t] = k
        fid = obj.get("frame_id", "")
        frame_ids.setdefault(str(fid), k)
        if len(frame_ids) > 1:
            a, b = list(frame_ids)[:2]
            raise dec.fail(k, f"frame_id {b!r} differs from {a!r} of message {frame_ids[a]}: markers must share one frame")
        X, ids = _cloud_points(dec, k, obj)
        out = np.full((M, 3), np.nan)
        if ids is None:
            if len(X) != M:
                raise dec.fail(k, f"{len(X)} points, but the labels name {M} markers (without an 'id' field, "
                               "point k is marker k, so every cloud holds one point per label)")
            out = X
        else:
            if not np.all((ids >= 0) & (ids < M) & (ids == np.round(ids))):
                raise dec.fail(k, f"an 'id' is not a label index 0-{M - 1}")
            iid = ids.astype(np.int64)
            if len(np.unique(iid)) != len(iid):
                raise dec.fail(k, "two points have the same 'id'")
            out[iid] = X
        clouds.append(out)
        times.append(t)
    try:
        fps = float(meta.get("fps", ch.metadata.get("fps", "nan")))
    except ValueError:
        fps = float("nan")
    idx, fps, F = _frame_grid(p, times, fps if math.isfinite(fps) and fps > 0 else None, None)
    check_grid(p, F, M, len(clouds) * M)
    if len(np.unique(idx)) != len(idx):
        raise InputError(f"{ch.topic}: two clouds fall on one frame at {fps:.6g} fps (timestamps closer than a "
                         "frame); give the right fps in the metadata", path=p)
    P = np.full((F, M, 3), np.nan)
    P[idx] = np.array(clouds)
    return labels, P, times, fps
