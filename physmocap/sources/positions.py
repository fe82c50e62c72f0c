"""Joint-position (tracker) recordings: CSV, NPZ and JSON-lines.

Each file holds per-frame 3D positions of named joints, optionally with a
per-joint confidence in [0, 1] (NaN, an empty cell, ``null`` or a missing
joint mean "not tracked this frame").  The three formats:

**CSV** (``.csv``), one header row, then one row per frame ("wide")::

    frame,time,head_x,head_y,head_z,head_conf,neck_x,...

``time`` (or ``timestamp``) is in seconds and optional when the frame rate
is known; ``frame`` is optional; every joint needs ``_x``, ``_y``, ``_z``
columns (``.x`` works too) and may have ``_conf`` / ``_confidence``.  Or one
row per joint per frame ("long"): columns ``frame`` (or ``time``), ``joint``,
``x``, ``y``, ``z`` and optionally ``confidence``.  Lines starting with
``#`` before the header may carry options as ``# key: value`` (``fps``,
``units``, ``frame``, ``up``, ``mirrored``, ``profile``).

**NPZ** (``.npz``, read without pickle): ``positions (F, J, 3)``, ``names
(J,)`` (a string array; ``joint_names`` also works), optionally
``confidence (F, J)``, ``fps`` (scalar) or ``times (F,)`` in seconds, and the
scalar options above as 0-d string arrays.

**JSON lines** (``.jsonl``): one JSON object per line.  Objects before the
first frame are headers with options (``fps``, ``units``...); a frame is
``{"frame": 0, "time": 0.0, "joints": {"head": [x, y, z, conf], ...}}``, a
joint being ``[x, y, z]``, ``[x, y, z, confidence]``, ``{"x":.., "y":..,
"z":.., "confidence":..}`` or ``null``.

From the file to a positional :class:`~physmocap.motion.Motion`
(:func:`positional_motion`): units and the sensor's frame
(:mod:`physmocap.sources.sensor`), gaps (:mod:`physmocap.sources.gaps`),
optional One Euro smoothing (:mod:`physmocap.filters`), levelling and the
floor from the feet, the pelvis synthesised as the midpoint of the hips where
the tracker has none, and a skeleton whose hierarchy follows the canonical
joint set (:mod:`physmocap.canonical`) through the name-mapping profiles.
The skeleton's rest offsets are the median bone vectors over the clip, each
expressed in the body's heading frame (facing +X, left +Y, up +Z), with the
root at its median height; they describe a typical pose of the clip, not a
T-pose.  Joints the profile does not know hang from their nearest mapped joint.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..canonical import CANONICAL_NAMES, canonical_parent
from ..errors import InputError, MappingError, OptionError, warn
from ..fileio import parse_json
from . import FPS_RANGE, MAX_DISTANCE, check_distances, check_grid, pick_reader
from ..motion import Motion, Skeleton
from .gaps import fill_gaps, invalid_samples
from .sensor import Ground, default_foot_height, estimate_ground, guess_units, level_rotation, to_world, unit_scale

__all__ = [
    "read_positions",
    "positional_motion",
    "TRACKER_LAYOUTS",
    "known_layout",
    "RawPositions",
    "DEFAULT_MAX_GAP",
    "DEFAULT_MIN_CONFIDENCE",
]

#: Joint order of each tracker SDK's output (used to name unnamed pose arrays).
TRACKER_LAYOUTS: dict[str, tuple[str, ...]] = {
    # NiTE 2 nite::JointType order (JOINT_HEAD = 0 ... JOINT_RIGHT_FOOT = 14).
    "nite": (
        "head", "neck", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
        "left_hand", "right_hand", "torso", "left_hip", "right_hip", "left_knee",
        "right_knee", "left_foot", "right_foot",
    ),
    # Kinect for Windows SDK 2.0 JointType order (SpineBase = 0 ... ThumbRight = 24).
    "kinect_v2": (
        "SpineBase", "SpineMid", "Neck", "Head", "ShoulderLeft", "ElbowLeft", "WristLeft",
        "HandLeft", "ShoulderRight", "ElbowRight", "WristRight", "HandRight", "HipLeft",
        "KneeLeft", "AnkleLeft", "FootLeft", "HipRight", "KneeRight", "AnkleRight",
        "FootRight", "SpineShoulder", "HandTipLeft", "ThumbLeft", "HandTipRight", "ThumbRight",
    ),
    # Azure Kinect Body Tracking k4abt_joint_id_t order (PELVIS = 0 ... EAR_RIGHT = 31).
    "azure_kinect": (
        "PELVIS", "SPINE_NAVEL", "SPINE_CHEST", "NECK", "CLAVICLE_LEFT", "SHOULDER_LEFT",
        "ELBOW_LEFT", "WRIST_LEFT", "HAND_LEFT", "HANDTIP_LEFT", "THUMB_LEFT",
        "CLAVICLE_RIGHT", "SHOULDER_RIGHT", "ELBOW_RIGHT", "WRIST_RIGHT", "HAND_RIGHT",
        "HANDTIP_RIGHT", "THUMB_RIGHT", "HIP_LEFT", "KNEE_LEFT", "ANKLE_LEFT", "FOOT_LEFT",
        "HIP_RIGHT", "KNEE_RIGHT", "ANKLE_RIGHT", "FOOT_RIGHT", "HEAD", "NOSE", "EYE_LEFT",
        "EAR_LEFT", "EYE_RIGHT", "EAR_RIGHT",
    ),
}  # fmt: skip

#: Longest gap (seconds) that is interpolated by default.
DEFAULT_MAX_GAP = 0.2
#: Samples below this confidence are treated as missing by default
#: (NITE's 0.5 "inferred" passes, its 0 "lost" does not).
DEFAULT_MIN_CONFIDENCE = 0.5
#: Name given to a synthesised pelvis joint.
PELVIS_NAME = "pelvis"

_HEADER_OPTIONS = ("fps", "units", "frame", "up", "mirrored", "profile", "floor_plane")


def known_layout(count: int) -> list[str] | None:
    """The joint names of the tracker layout with ``count`` joints, if any."""
    for names in TRACKER_LAYOUTS.values():
        if len(names) == count:
            return list(names)
    return None


# --- raw file contents ------------------------------------------------------------
@dataclass
class RawPositions:
    """What a file holds, before any convention is applied.

    ``positions (F, J, 3)`` in file units with NaN for untracked samples,
    ``confidence (F, J)`` or None, ``times (F,)`` seconds or None, and options
    found in the file (``fps``, ``units``...).
    """

    names: list[str]
    positions: np.ndarray
    confidence: np.ndarray | None = None
    times: np.ndarray | None = None
    options: dict[str, Any] = field(default_factory=dict)


_MISSING = {"", "nan", "NaN", "NAN", "-", "null", "None", "none", "NA", "n/a"}


def _cell(text: str, path: Path, line: int, column: str) -> float:
    t = text.strip()
    if t in _MISSING:
        return math.nan
    try:
        v = float(t)
    except ValueError:
        raise InputError(f"column {column!r}: {t!r} is not a number", path=path, line=line) from None
    return v if math.isfinite(v) else math.nan


def _parse_option_comment(line: str, options: dict[str, Any]) -> None:
    m = re.match(r"^#\s*([A-Za-z_]+)\s*[:=]\s*(.+?)\s*$", line)
    if m and m.group(1).lower() in _HEADER_OPTIONS:
        options[m.group(1).lower()] = m.group(2)


_AXIS_COL = re.compile(r"^(?P<joint>.+?)[_.\s](?P<axis>x|y|z|conf|confidence|c)$", re.IGNORECASE)
_TIME_COLS = ("time", "timestamp", "t")


def _read_csv(path: Path) -> RawPositions:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError("not a text CSV file (it is not UTF-8)", path=path) from None
    lines = text.splitlines()
    options: dict[str, Any] = {}
    start = 0
    while start < len(lines) and (not lines[start].strip() or lines[start].lstrip().startswith("#")):
        _parse_option_comment(lines[start].strip(), options)
        start += 1
    if start >= len(lines):
        raise InputError("empty CSV file: expected a header row of column names", path=path)
    dialect = csv.excel
    try:
        dialect = csv.Sniffer().sniff(lines[start], delimiters=",;\t")
    except csv.Error:
        pass
    rows = list(csv.reader(io.StringIO("\n".join(lines[start:])), dialect))
    header = [h.strip() for h in rows[0]]
    lower = [h.lower() for h in header]
    header_line = start + 1
    body = [(header_line + 1 + k, r) for k, r in enumerate(rows[1:]) if any(c.strip() for c in r)]
    if not body:
        raise InputError("the CSV file has a header but no data rows", path=path, line=header_line)
    for ln, r in body:
        if len(r) != len(header):
            raise InputError(
                f"row has {len(r)} cells, the header has {len(header)} columns", path=path, line=ln
            )
    if "joint" in lower:
        return _read_csv_long(path, header, lower, body, options, header_line)

    time_col = next((lower.index(c) for c in _TIME_COLS if c in lower), None)
    joints: dict[str, dict[str, int]] = {}
    order: list[str] = []
    for k, h in enumerate(header):
        m = _AXIS_COL.match(h)
        if not m or k == time_col:
            continue
        joint = m.group("joint")
        axis = m.group("axis").lower()
        axis = "conf" if axis in ("c", "confidence") else axis
        if joint not in joints:
            joints[joint] = {}
            order.append(joint)
        joints[joint][axis] = k
    if not joints:
        raise InputError(
            "no joint columns: expected <joint>_x, <joint>_y, <joint>_z per joint (wide CSV) or "
            f"columns joint, x, y, z (long CSV); the header has {header[:8]}",
            path=path,
            line=header_line,
        )
    for j in order:
        lacking = [a for a in "xyz" if a not in joints[j]]
        if lacking:
            have = ", ".join(header[joints[j][a]] for a in joints[j])
            raise InputError(
                f"joint {j!r} has columns {have} but no {', '.join(f'{j}_{a}' for a in lacking)}",
                path=path,
                line=header_line,
            )
    F, J = len(body), len(order)
    pos = np.empty((F, J, 3))
    has_conf = any("conf" in joints[j] for j in order)
    conf = np.ones((F, J)) if has_conf else None
    times = np.empty(F) if time_col is not None else None
    for f, (ln, r) in enumerate(body):
        for jj, j in enumerate(order):
            cols = joints[j]
            for a, axis in enumerate("xyz"):
                pos[f, jj, a] = _cell(r[cols[axis]], path, ln, header[cols[axis]])
            if conf is not None and "conf" in cols:
                conf[f, jj] = _cell(r[cols["conf"]], path, ln, header[cols["conf"]])
        if times is not None:
            times[f] = _cell(r[time_col], path, ln, header[time_col])
    return RawPositions(order, pos, conf, times, options)


def _read_csv_long(
    path: Path,
    header: list[str],
    lower: list[str],
    body: list[tuple[int, list[str]]],
    options: dict[str, Any],
    header_line: int,
) -> RawPositions:
    lacking = [c for c in ("x", "y", "z") if c not in lower]
    key_col = lower.index("frame") if "frame" in lower else None
    time_col = next((lower.index(c) for c in _TIME_COLS if c in lower), None)
    if lacking or (key_col is None and time_col is None):
        need = lacking + ([] if key_col is not None or time_col is not None else ["frame or time"])
        raise InputError(
            f"long CSV (one row per joint) lacks column(s) {', '.join(need)}; expected "
            "frame (or time), joint, x, y, z[, confidence]",
            path=path,
            line=header_line,
        )
    jc = lower.index("joint")
    xc, yc, zc = (lower.index(a) for a in "xyz")
    cc = next((lower.index(c) for c in ("confidence", "conf", "c") if c in lower), None)
    names: list[str] = []
    col: dict[str, int] = {}
    keys: list[float] = []
    kidx: dict[float, int] = {}
    entries = []
    for ln, r in body:
        name = r[jc].strip()
        if not name:
            raise InputError("empty joint name", path=path, line=ln)
        key_text = r[key_col] if key_col is not None else r[time_col]  # type: ignore[index]
        key = _cell(key_text, path, ln, header[key_col if key_col is not None else time_col])  # type: ignore[index]
        if not math.isfinite(key):
            raise InputError("missing frame number / time", path=path, line=ln)
        if name not in col:
            col[name] = len(names)
            names.append(name)
        if key not in kidx:
            kidx[key] = len(keys)
            keys.append(key)
        p = [_cell(r[c], path, ln, header[c]) for c in (xc, yc, zc)]
        c = _cell(r[cc], path, ln, header[cc]) if cc is not None else 1.0
        t = _cell(r[time_col], path, ln, header[time_col]) if time_col is not None else math.nan
        entries.append((kidx[key], col[name], p, c, t))
    order = np.argsort(np.asarray(keys), kind="stable")
    rank = np.empty(len(keys), dtype=int)
    rank[order] = np.arange(len(keys))
    F, J = len(keys), len(names)
    check_grid(path, F, J, len(entries))
    pos = np.full((F, J, 3), np.nan)
    conf = np.ones((F, J)) if cc is not None else None
    times = np.full(F, np.nan) if time_col is not None else None
    for k, j, p, c, t in entries:
        f = rank[k]
        pos[f, j] = p
        if conf is not None:
            conf[f, j] = c
        if times is not None:
            times[f] = t
    if conf is not None:
        conf = np.where(np.all(np.isfinite(pos), axis=-1), conf, 0.0)
    return RawPositions(names, pos, conf, times, options)


def _read_npz(path: Path) -> RawPositions:
    from ..fileio import npz_array, npz_strings, npz_text, read_npz

    arrays = read_npz(path, "a readable NPZ archive of tracker positions")
    if "positions" not in arrays:
        raise InputError(f"NPZ has no 'positions' array (F, J, 3); it has {sorted(arrays)}", path=path)
    pos = npz_array(arrays["positions"], "positions", path, ("F", "J", 3))
    F, J = pos.shape[:2]
    names_key = "names" if "names" in arrays else "joint_names"
    if names_key not in arrays:
        names = known_layout(J)
        if names is None:
            raise InputError(
                f"NPZ has no 'names' array and {J} joints match no known tracker layout "
                f"({', '.join(f'{k}: {len(v)}' for k, v in TRACKER_LAYOUTS.items())})",
                path=path,
            )
    else:
        names = npz_strings(arrays[names_key], names_key, path, J)
    conf = arrays.get("confidence")
    if conf is not None:
        conf = npz_array(conf, "confidence", path, (F, J))
    times_key = "times" if "times" in arrays else "time"
    times = arrays.get(times_key)
    if times is not None:
        times = npz_array(times, times_key, path, (F,))
    options: dict[str, Any] = {}
    for key in _HEADER_OPTIONS:
        if key in arrays:
            a = arrays[key]
            if a.dtype.kind in "US":
                options[key] = npz_text(a, key, path)
            elif a.size == 1 and a.dtype.kind in "biuf":
                options[key] = a.reshape(-1)[0].item()
            elif key == "floor_plane" and a.ndim == 1 and a.size <= 4 and a.dtype.kind in "iuf":
                options[key] = a.tolist()
            else:
                raise InputError(f"'{key}' must be a single value, got {a.dtype} {a.shape}", path=path)
    return RawPositions(names, pos, conf, times, options)


def _read_jsonl(path: Path) -> RawPositions:
    options: dict[str, Any] = {}
    frames: list[tuple[int, dict]] = []
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", path=path) from None
    try:
        lines = data.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(f"not a UTF-8 text file (byte 0x{data[exc.start]:02x})", path=path, line=line) from None
    for ln, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            obj = parse_json(line, nan_constants=True)
        except ValueError as exc:
            raise InputError(f"invalid JSON ({exc})", path=path, line=ln) from None
        if not isinstance(obj, dict):
            raise InputError("expected a JSON object per line", path=path, line=ln)
        if "joints" in obj:
            frames.append((ln, obj))
        elif frames:
            raise InputError("a line without 'joints' after the first frame", path=path, line=ln)
        else:
            for k, v in obj.items():
                if k in _HEADER_OPTIONS or k == "joint_names":
                    options[k] = v
    if not frames:
        raise InputError("no frames: expected lines like {\"joints\": {\"head\": [x, y, z]}}", path=path)
    listed = options.pop("joint_names", [])
    if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
        raise InputError("'joint_names' must be a list of names", path=path)
    names: list[str] = list(listed)
    col = {n: i for i, n in enumerate(names)}
    parsed = []
    any_time = False
    for ln, obj in frames:
        joints = obj["joints"]
        items: list[tuple[str, Any]]
        if isinstance(joints, dict):
            items = list(joints.items())
        elif isinstance(joints, list) and all(isinstance(x, dict) and "name" in x for x in joints):
            items = [(x["name"], x) for x in joints]
        else:
            raise InputError(
                "'joints' must be an object of name -> [x, y, z(, confidence)] or a list of "
                "{\"name\", \"position\"} objects",
                path=path,
                line=ln,
            )
        vals = []
        for name, v in items:
            name = str(name)
            if name not in col:
                col[name] = len(names)
                names.append(name)
            vals.append((col[name], _jsonl_joint(v, path, ln, name)))
        t = obj.get("time", obj.get("timestamp"))
        if t is not None:
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
                raise InputError(f"'time' must be a finite number of seconds, got {str(t)[:40]}", path=path,
                                 line=ln)
            any_time = True
        parsed.append((vals, t))
    F, J = len(parsed), len(names)
    check_grid(path, F, J, sum(len(vals) for vals, _ in parsed))
    pos = np.full((F, J, 3), np.nan)
    conf = np.zeros((F, J))
    has_conf = False
    times = np.full(F, np.nan) if any_time else None
    for f, (vals, t) in enumerate(parsed):
        for j, (p, c) in vals:
            pos[f, j] = p
            if c is not None:
                has_conf = True
            conf[f, j] = 1.0 if c is None else c
        if times is not None:
            times[f] = math.nan if t is None else float(t)
    conf = np.where(np.all(np.isfinite(pos), axis=-1), conf, 0.0)
    return RawPositions(names, pos, conf if has_conf else None, times, options)


def _jsonl_joint(v: Any, path: Path, ln: int, name: str) -> tuple[list[float], float | None]:
    def num(x: Any) -> float:
        if x is None:
            return math.nan
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise InputError(f"joint {name!r}: {x!r} is not a number", path=path, line=ln)
        return float(x) if math.isfinite(x) else math.nan

    if v is None:
        return [math.nan] * 3, 0.0
    if isinstance(v, list):
        if len(v) not in (3, 4):
            raise InputError(f"joint {name!r}: expected [x, y, z] or [x, y, z, confidence]", path=path, line=ln)
        return [num(x) for x in v[:3]], (num(v[3]) if len(v) == 4 else None)
    if isinstance(v, dict):
        if "position" in v:
            p = v["position"]
            if isinstance(p, dict):
                p = [p.get(a) for a in "xyz"]
            if not isinstance(p, list) or len(p) != 3:
                raise InputError(f"joint {name!r}: 'position' must be [x, y, z]", path=path, line=ln)
            xyz = [num(x) for x in p]
        else:
            lacking = [a for a in "xyz" if a not in v]
            if lacking:
                raise InputError(f"joint {name!r} lacks {', '.join(lacking)}", path=path, line=ln)
            xyz = [num(v[a]) for a in "xyz"]
        c = v.get("confidence", v.get("conf"))
        return xyz, (None if c is None else num(c))
    raise InputError(f"joint {name!r}: expected [x, y, z] or an object", path=path, line=ln)


_READERS = {".csv": _read_csv, ".npz": _read_npz, ".jsonl": _read_jsonl}


# --- the pipeline -----------------------------------------------------------------
def _to_bool(value: Any, name: str, path: Path) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)) and value in (0, 1):
        return bool(value)
    s = str(value).strip().lower()
    if s in ("1", "true", "yes", "on"):
        return True
    if s in ("0", "false", "no", "off"):
        return False
    raise OptionError(f"{name} must be true or false, got {value!r}", path=path)


def _to_float(value: Any, name: str, path: Path) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise OptionError(f"{name} must be a number, got {value!r}", path=path) from None
    if not math.isfinite(v):
        raise OptionError(f"{name} must be finite, got {value!r}", path=path)
    return v


def _uniform_frames(
    pos: np.ndarray, conf: np.ndarray | None, times: np.ndarray | None, fps: float | None, path: Path
) -> tuple[np.ndarray, np.ndarray | None, float, int]:
    """Place frames on a uniform grid; returns positions, confidence, fps and dropped duplicates."""
    if times is None or not np.isfinite(times).any():
        if fps is None:
            raise InputError("no frame rate: give fps= (or --fps), or a time column in seconds", path=path)
        return pos, conf, float(fps), 0
    if not np.isfinite(times).all():
        bad = int(np.flatnonzero(~np.isfinite(times))[0])
        raise InputError("missing time value", path=path, frame=bad)
    t = times - times[0]
    if fps is None:
        dt = np.diff(np.unique(t))
        if dt.size == 0:
            raise InputError("all frames have the same time; give fps=", path=path)
        fps = 1.0 / float(np.median(dt))
        lo, hi = FPS_RANGE
        if not lo <= fps <= hi:
            raise InputError(
                f"the times' median spacing gives {fps:.6g} fps, outside {lo:g}-{hi:g}; give fps=", path=path
            )
    if np.any(np.diff(times) < 0):
        order = np.argsort(times, kind="stable")
        pos, t = pos[order], t[order]
        conf = None if conf is None else conf[order]
        t = t - t.min()
    fidx = np.rint(t * fps)  # float: no int64 overflow before the check
    if not fidx.max() + 1 <= 4 * len(fidx) + 10:
        raise InputError(
            f"times do not fit {fps:g} fps (they would span {fidx.max() + 1:.6g} frames); give fps=", path=path
        )
    idx = fidx.astype(np.int64)
    F = int(idx.max()) + 1
    if F == len(idx) and np.all(idx == np.arange(F)):
        return pos, conf, float(fps), 0
    out = np.full((F,) + pos.shape[1:], np.nan)
    out[idx] = pos  # later samples win on a shared frame
    oc = None
    if conf is not None:
        oc = np.zeros((F,) + conf.shape[1:])
        oc[idx] = conf
    dropped = len(idx) - len(np.unique(idx))
    return out, oc, float(fps), dropped


def _canonical_indices(
    names: Sequence[str], profile: str | None, mapping: Any, path: Path
) -> tuple[dict[str, int], str | None]:
    """Canonical joint -> index into ``names`` via the name-mapping profiles."""
    from .profiles import map_skeleton  # type: ignore[attr-defined]

    J = len(names)
    probe = Skeleton(names=tuple(names), parents=-np.ones(J, dtype=np.int64), offsets=np.zeros((J, 3)))
    try:
        jmap = map_skeleton(probe, profile=profile, mapping=mapping)
    except MappingError as exc:
        if profile is not None or mapping is not None:
            raise
        warn(f"{path}: joint names not recognised ({exc}); no hierarchy, levelling or floor from the feet")
        return {}, None
    indices = {str(k): int(v) for k, v in dict(jmap.indices).items()}
    return indices, getattr(jmap, "profile", None)


def _heading(left_hip: np.ndarray, right_hip: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` yaw-only frames (x forward, y left, z up) from the hip line."""
    y = left_hip - right_hip
    y[..., 2] = 0.0
    n = np.linalg.norm(y, axis=-1, keepdims=True)
    y = np.where(n > 1e-9, y / np.maximum(n, 1e-9), np.array([0.0, 1.0, 0.0]))
    z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), y.shape)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def _hierarchy(
    names: list[str], canon: dict[str, int], positions: np.ndarray
) -> tuple[list[int], list[int]]:
    """Joint order (parents first) and parents (in the new order) from the canonical tree."""
    J = len(names)
    by_joint = {j: c for c, j in canon.items()}
    mapped = sorted(by_joint, key=lambda j: CANONICAL_NAMES.index(by_joint[j]))
    present = set(canon)
    parent_old: dict[int, int] = {}
    for j in mapped:
        pc = canonical_parent(by_joint[j], present)
        parent_old[j] = -1 if pc is None else canon[pc]
    unmapped = [j for j in range(J) if j not in by_joint]
    if mapped:
        ok = np.all(np.isfinite(positions), axis=-1)
        med = np.full((J, 3), np.inf)
        for j in range(J):
            if ok[:, j].any():
                med[j] = np.median(positions[ok[:, j], j], axis=0)
        for j in unmapped:
            with np.errstate(invalid="ignore"):
                d = np.linalg.norm(med[mapped] - med[j], axis=-1)
            d = np.where(np.isfinite(d), d, np.inf)
            parent_old[j] = mapped[int(np.argmin(d))]
    else:
        for j in unmapped:
            parent_old[j] = -1
    order = mapped + unmapped
    new = {old: k for k, old in enumerate(order)}
    parents = [-1 if parent_old[o] < 0 else new[parent_old[o]] for o in order]
    return order, parents


def _rest_offsets(
    positions: np.ndarray, valid: np.ndarray, parents: list[int], heading: np.ndarray | None
) -> np.ndarray:
    """Median bone vectors in the heading frame (see the module docstring)."""
    F, J = positions.shape[:2]
    offsets = np.zeros((J, 3))
    for j, p in enumerate(parents):
        if p < 0:
            ok = valid[:, j]
            z = positions[ok, j, 2] if ok.any() else positions[:, j, 2]
            offsets[j] = [0.0, 0.0, float(np.median(z))]
            continue
        ok = valid[:, j] & valid[:, p]
        if not ok.any():
            continue
        v = positions[ok, j] - positions[ok, p]
        if heading is not None:
            v = np.einsum("fji,fj->fi", heading[ok], v)  # R^T v
        med = np.median(v, axis=0)
        length = float(np.median(np.linalg.norm(v, axis=-1)))
        n = np.linalg.norm(med)
        offsets[j] = med / n * length if n > 1e-9 else med
    return offsets


def positional_motion(
    names: Sequence[str],
    positions: np.ndarray,
    confidence: np.ndarray | None,
    fps: float | None,
    path: str | os.PathLike,
    *,
    times: np.ndarray | None = None,
    units: str | float | None = "auto",
    frame: str = "camera",
    up: str = "Y",
    mirrored: bool | str = True,
    level: bool | str = True,
    floor: str | float | None = "auto",
    floor_plane: Sequence[float] | None = None,
    foot_height: float | None = None,
    profile: str | None = None,
    mapping: Any = None,
    min_confidence: float = DEFAULT_MIN_CONFIDENCE,
    max_gap: float = DEFAULT_MAX_GAP,
    smooth: bool | dict | None = False,
    synthesize: bool = True,
) -> Motion:
    """Turn raw tracker positions into a positional :class:`Motion` (metres, Z-up).

    Args:
        names: ``(J,)`` joint names as the tracker calls them.
        positions: ``(F, J, 3)`` in file units; NaN where untracked.
        confidence: ``(F, J)`` in [0, 1] or None.
        fps: Frame rate; None derives it from ``times``.
        path: The source file, for messages.
        times: ``(F,)`` seconds; frames are placed on a uniform grid
            (missing grid frames become lost frames).
        units: ``"auto"``, a unit name (``mm``, ``m``...) or metres per unit.
        frame: ``"camera"`` or ``"world"`` (:func:`physmocap.sources.sensor.to_world`).
        up: Up axis of a world frame (``"Y"`` or ``"Z"``).
        mirrored: Camera frame: +X points to the performer's right.
        level: Rotate so the estimated (or given) up axis is +Z.
        floor: ``"auto"`` puts the estimated floor at z = 0; a number is the
            floor's height in metres (after levelling) to move to z = 0;
            None leaves heights alone.
        floor_plane: ``(a, b, c, d)``, the floor as ``a x + b y + c z + d = 0``
            in the file's frame and units with ``(a, b, c)`` pointing up (the
            Kinect SDK's FloorClipPlane); overrides the estimate.
        foot_height: Height of the lowest foot joints above the floor when
            standing (m); None uses :func:`physmocap.sources.sensor.default_foot_height`.
        profile, mapping: Name-mapping profile / mapping file for the joints.
        min_confidence: Samples below this confidence are missing.
        max_gap: Longest gap (seconds) filled by interpolation.
        smooth: One Euro filter: True for the defaults, or a dict of
            ``min_cutoff``, ``beta``, ``d_cutoff``.
        synthesize: Add a pelvis at the midpoint of the hips when the tracker has none.
    """
    p = Path(path)
    names = [str(n) for n in names]
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[1] != len(names):
        raise InputError(f"positions must be (F, {len(names)}, 3), got {pos.shape}", path=p)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"duplicate joint names {dup}", path=p)
    if pos.shape[0] == 0 or pos.shape[1] == 0:
        raise InputError("no frames or no joints", path=p)
    conf = None if confidence is None else np.asarray(confidence, dtype=float)
    if fps is not None:
        try:
            fps = float(fps)
        except (TypeError, ValueError):
            raise OptionError(f"fps must be a number, got {fps!r}", path=p) from None
        if not (math.isfinite(fps) and fps > 0):
            raise OptionError(f"fps must be positive, got {fps}", path=p)
    min_confidence = _to_float(min_confidence, "min_confidence", p)
    max_gap = _to_float(max_gap, "max_gap", p)
    if not (0.0 <= min_confidence <= 1.0):
        raise OptionError(f"min_confidence must be in [0, 1], got {min_confidence}", path=p)
    if not (max_gap >= 0.0):
        raise OptionError(f"max_gap must be >= 0 seconds, got {max_gap}", path=p)
    if isinstance(floor, str) and floor.strip().lower() in ("none", "keep", "off"):
        floor = None
    elif isinstance(floor, str) and floor.strip().lower() != "auto":
        floor = _to_float(floor, "floor", p)
    if isinstance(floor_plane, str):
        try:
            floor_plane = [float(x) for x in re.split(r"[,\s]+", floor_plane.strip().strip("()[]")) if x]
        except ValueError:
            raise OptionError(f"floor_plane must be four numbers a, b, c, d, got {floor_plane!r}", path=p) from None
    if foot_height is not None:
        foot_height = _to_float(foot_height, "foot_height", p)
    mirrored = _to_bool(mirrored, "mirrored", p)
    level = _to_bool(level, "level", p)
    frame = str(frame).lower()
    if frame not in ("camera", "world"):
        raise OptionError(f"frame must be 'camera' or 'world', got {frame!r}", path=p)
    up = str(up).upper()
    if up not in ("Y", "Z"):
        raise OptionError(f"up must be Y or Z, got {up!r}", path=p)

    pos, conf, fps, dropped = _uniform_frames(pos, conf, times, fps, p)
    if dropped:
        warn(f"{p}: {dropped} sample(s) share a frame slot with another at {fps:g} fps; kept the later")
    F, J = pos.shape[:2]

    # units and frame
    if units is None or (isinstance(units, str) and units.lower() == "auto"):
        unit_name = guess_units(pos)
    else:
        unit_name = units  # type: ignore[assignment]
    unit_name, scale = unit_scale(unit_name, p)
    file_up = "Y" if frame == "camera" else up
    with np.errstate(over="ignore", invalid="ignore"):
        pos = to_world(pos * scale, frame=frame, up=up, mirrored=mirrored)
    check_distances(pos, p, "joint", names)  # before any fit: 1e308 would break the ground's SVD
    plane_up = None
    plane_floor = None
    if floor_plane is not None:
        plane = np.asarray(floor_plane, dtype=float).reshape(-1)
        if plane.shape != (4,) or not np.all(np.isfinite(plane)) or np.linalg.norm(plane[:3]) < 1e-12:
            raise OptionError(f"floor_plane must be 4 finite numbers (a, b, c, d), got {floor_plane!r}", path=p)
        n = np.linalg.norm(plane[:3])
        plane_up = to_world(plane[:3] / n, frame=frame, up=up, mirrored=mirrored)
        plane_floor = -plane[3] * scale / n
        if not abs(plane_floor) < MAX_DISTANCE:
            raise OptionError(f"floor_plane puts the floor {plane_floor:.3g} m away; expected within 1 km", path=p)

    # gaps
    bad = invalid_samples(pos, conf, float(min_confidence))
    max_gap_frames = int(round(float(max_gap) * fps))
    canon, profile_name = _canonical_indices(names, profile, mapping, p)
    order, parents = _hierarchy(names, canon, np.where(bad[..., None], np.nan, pos))
    parents_orig = np.full(J, -1, dtype=np.int64)
    for k, old in enumerate(order):
        parents_orig[old] = -1 if parents[k] < 0 else order[parents[k]]
    report = fill_gaps(pos, conf, names, max_gap_frames, float(min_confidence), parents=parents_orig)
    pos, conf_out = report.positions, report.confidence

    # smoothing (causal, restarts after masked stretches)
    if smooth:
        from ..filters import one_euro_filter

        params = dict(smooth) if isinstance(smooth, dict) else {}
        unknown = set(params) - {"min_cutoff", "beta", "d_cutoff"}
        if unknown:
            raise OptionError(f"unknown smoothing parameter(s) {sorted(unknown)}", path=p)
        pos = one_euro_filter(pos, fps=fps, valid=conf_out > 0.0, **params)

    # ground: up axis and floor
    feet: list[int] = []
    kinds: list[str] = []
    for side in ("left", "right"):
        for kind in ("toe", "ankle"):
            c = f"{side}_{kind}"
            if c in canon:
                feet.append(canon[c])
                kinds.append(kind)
                break
    top = [canon[c] for c in ("neck", "head", "chest") if c in canon]
    valid_meas = ~bad
    leg = []
    for side in ("left", "right"):
        chain = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        if all(c in canon for c in chain):
            a, b, c = (canon[x] for x in chain)
            ok = valid_meas[:, a] & valid_meas[:, b] & valid_meas[:, c]
            if ok.any():
                leg.append(
                    float(np.median(np.linalg.norm(pos[ok, a] - pos[ok, b], axis=-1)))
                    + float(np.median(np.linalg.norm(pos[ok, b] - pos[ok, c], axis=-1)))
                )
    leg_length = float(np.mean(leg)) if leg else None
    if foot_height is None:
        fh = float(np.mean([default_foot_height(k, leg_length) for k in kinds])) if kinds else 0.0
    else:
        fh = float(foot_height)
    ground: Ground | None = None
    if plane_up is not None:
        ground = Ground(up=plane_up, floor=float(plane_floor), method="given")  # type: ignore[arg-type]
    elif (level or (isinstance(floor, str) and floor == "auto")) and feet:
        ground = estimate_ground(pos, valid_meas, feet, top, fps, foot_height=fh)
    elif level or floor == "auto":
        warn(f"{p}: no feet mapped; the up axis and floor are not estimated")
    if level and ground is not None:
        pos = pos @ level_rotation(ground.up).T
    floor_z = 0.0
    floor_known = floor is not None
    if isinstance(floor, str):
        floor_known = ground is not None or bool(feet)
        if ground is not None and level:
            floor_z = ground.floor  # the floor's height along ``up`` is its z after levelling
        elif feet:
            z = pos[:, feet, 2][valid_meas[:, feet]]
            floor_z = (float(np.percentile(z, 10.0)) if z.size else 0.0) - fh
    elif floor is not None:
        floor_z = float(floor)
    pos = pos - np.array([0.0, 0.0, floor_z])

    # synthesised joints: the pelvis as the midpoint of the hips
    synthesized: list[str] = []
    conf_all = conf_out
    if synthesize and "pelvis" not in canon and "left_hip" in canon and "right_hip" in canon:
        name = PELVIS_NAME if PELVIS_NAME not in names else "pelvis_synth"
        lh, rh = canon["left_hip"], canon["right_hip"]
        pelvis = 0.5 * (pos[:, lh] + pos[:, rh])
        pc = np.minimum(conf_out[:, lh], conf_out[:, rh])
        names = names + [name]
        pos = np.concatenate([pos, pelvis[:, None]], axis=1)
        conf_all = np.concatenate([conf_out, pc[:, None]], axis=1)
        valid_meas = np.concatenate([valid_meas, (valid_meas[:, lh] & valid_meas[:, rh])[:, None]], axis=1)
        canon = dict(canon)
        canon["pelvis"] = len(names) - 1
        synthesized.append(name)
        order, parents = _hierarchy(names, canon, pos)

    # skeleton in parent-first order
    order_arr = np.asarray(order)
    names_o = [names[k] for k in order]
    pos_o = pos[:, order_arr]
    conf_o = conf_all[:, order_arr]
    new_index = {old: k for k, old in enumerate(order)}
    canon_o = {c: new_index[j] for c, j in canon.items()}
    heading = None
    if "left_hip" in canon_o and "right_hip" in canon_o:
        heading = _heading(pos_o[:, canon_o["left_hip"]], pos_o[:, canon_o["right_hip"]])
    offsets = _rest_offsets(pos_o, conf_o > 0.0, parents, heading)
    skeleton = Skeleton(names=tuple(names_o), parents=np.asarray(parents), offsets=offsets)

    if not np.all(np.isfinite(pos_o)):  # pragma: no cover - guarded by fill_gaps
        raise InputError("internal error: non-finite positions after gap filling", path=p)
    meta: dict[str, Any] = {
        "tracker": {
            "profile": profile_name,
            "frame": frame,
            "mirrored": bool(mirrored) if frame == "camera" else None,
            "units": unit_name,
            "synthesized": synthesized,
            "joint_map": {c: names_o[j] for c, j in sorted(canon_o.items(), key=lambda kv: kv[1])},
            "ground": None
            if ground is None
            else {
                "method": ground.method,
                "up": [float(x) for x in ground.up],
                "levelled": bool(level),
                "floor_offset_m": float(floor_z),
                "foot_height_m": fh,
                "stance_points": ground.stance_points,
                "spread_m": [float(x) for x in ground.spread],
            },
            "min_confidence": float(min_confidence),
            "max_gap_frames": max_gap_frames,
            "smoothed": bool(smooth),
        },
        "gaps": report.gaps,
        "gap_summary": report.summary(),
    }
    if floor_known:
        meta["floor_z"] = 0.0
    if canon_o:
        # The mapping used here, incl. synthesised joints, as a mapping dict for
        # physmocap.sources.profiles.map_skeleton(motion, mapping=...).
        meta["source_mapping"] = {
            "profile": profile_name if profile_name not in (None, "custom") else "none",
            "joints": dict(meta["tracker"]["joint_map"]),
        }
    return Motion(
        skeleton=skeleton,
        fps=float(fps),
        positions=pos_o,
        confidence=np.clip(conf_o, 0.0, 1.0),
        source=str(p),
        units=unit_name,
        unit_scale=scale,
        file_up=file_up,
        meta=meta,
    )


def read_positions(path: str | os.PathLike, **options: Any) -> Motion:
    """Read a joint-position file (``.csv``, ``.npz``, ``.jsonl``) into a positional Motion.

    Options (keyword arguments) are those of :func:`positional_motion`, plus
    ``fps``; they override options written in the file.  Defaults suit a
    tracker's camera-frame output: ``units="auto"``, ``frame="camera"``,
    ``mirrored=True``, levelled, floor at z = 0.
    """
    p, read = pick_reader(path, _READERS, "a joint-position file")
    allowed = {
        "fps", "units", "frame", "up", "mirrored", "level", "floor", "floor_plane", "foot_height",
        "profile", "mapping", "min_confidence", "max_gap", "smooth", "synthesize", "joint_names",
    }  # fmt: skip
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise OptionError(f"unknown option(s) {unknown} for joint-position files; known: {sorted(allowed)}", path=p)
    raw = read(p)
    check_grid(p, raw.positions.shape[0], raw.positions.shape[1], raw.positions.shape[0] * raw.positions.shape[1])
    opts: dict[str, Any] = {}
    for key, value in raw.options.items():
        if key == "fps":
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise InputError(f"fps in the file is not a number: {value!r}", path=p) from None
        opts[key] = value
    opts.update({k: v for k, v in options.items() if v is not None or k in ("floor",)})
    names = raw.names
    jn = opts.pop("joint_names", None)
    if jn is not None:
        if len(jn) != len(names):
            raise OptionError(f"joint_names has {len(jn)} names, the file has {len(names)} joints", path=p)
        names = [str(n) for n in jn]
    fps = opts.pop("fps", None)
    return positional_motion(names, raw.positions, raw.confidence, fps, p, times=raw.times, **opts)
