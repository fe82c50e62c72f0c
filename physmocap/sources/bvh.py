"""Read BVH (Biovision Hierarchy) files into a :class:`~physmocap.motion.Motion`.

A BVH file is a ``HIERARCHY`` section (a tree of ``ROOT``/``JOINT`` blocks with
an ``OFFSET``, a ``CHANNELS`` list and ``End Site`` leaves) followed by a
``MOTION`` section (``Frames:``, ``Frame Time:`` and one row of numbers per
frame, the channels of every joint in hierarchy order).

Conventions this reader assumes (they are what every exporter we know writes):

* Rotation channels are Euler angles in **degrees**, applied **intrinsically
  in the order they are listed**: ``Zrotation Xrotation Yrotation`` means
  ``R = Rz(a) Rx(b) Ry(c)`` (see :mod:`physmocap.rotations`).  A joint may list
  any subset of the three axes in any order; missing axes are zero.
* Position channels, on any joint, are the joint's local translation in its
  parent's frame and **replace** the ``OFFSET`` components they animate (the
  components a joint does not animate keep their offset).  They are applied
  before the joint's rotation, wherever they appear in the channel list.
* The file is Y-up unless told otherwise (``up="Z"``) or unless both its rest pose and its
  motion stand much taller along Z than along Y (a Z-up export, such as MakeHuman's; read as
  Z-up with a warning naming ``up="Y"``).  Lengths are in the
  file's unit, detected from the size of the rest pose unless given
  (:func:`detect_units`).

Every motion leaves the reader in the :class:`~physmocap.motion.Motion`
conventions: metres, Z-up, local rotations as x-y-z-w quaternions.  With the
file's up axis mapped to +Z by the signed axis permutation ``M``
(:func:`~physmocap.rotations.up_axis_matrix`), offsets and translations become
``s M t`` (``s`` metres per file unit) and local rotations ``M R M^T``, which for
a quaternion is ``(M v, w)``; forward kinematics then gives ``s M x`` for every
world position ``x`` of the file.

End sites become joints with ``end_site=True`` named ``<parent>_End`` (then
``<parent>_End2`` ... if a joint has several, skipping names already taken).

Bad files raise one :class:`~physmocap.errors.InputError` naming the file, the
1-based line and what was expected.  Where the only problem is a ``Frames:``
count that disagrees with the rows present, the rows present are read and a
warning is issued.  If the file ends in the middle of a row (fewer numbers
than channels, or a last number cut to ``-`` or ``1e``) while ``Frames:``
promises more rows than are complete (an interrupted copy or export), that
partial row is dropped with a warning; a short row anywhere else, or one that
``Frames:`` does not promise, is an error.  (A last number cut to a shorter
valid number, ``12.3`` from ``12.34``, cannot be told from a complete row.)
Numbers are decimal (``-1``, ``.5``, ``2.``, ``1e-3``); ``nan``, ``inf`` and
magnitudes above :data:`MAX_ABS_VALUE` are errors.  Duplicate joint names are
made unique with a warning.

Speed and memory: the ``MOTION`` block is read in 1 MB chunks, each parsed in
bulk by numpy's C text parser (a pure-Python pass re-reads a chunk only to
locate and describe an error exactly) and converted to quaternions with
vectorised numpy, so memory is the output arrays (``F x J x 4`` float64
rotations: 32 bytes per joint and frame, end sites included) plus about 30 MB.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError, warn
from ..motion import Motion, Skeleton, forward_kinematics
from ..rotations import euler_to_quat, up_axis_matrix
from ..spill import release, spilled_empty

__all__ = [
    "CHANNEL_NAMES",
    "UNIT_SCALES",
    "CMU_UNIT",
    "MAX_ABS_VALUE",
    "read_bvh",
    "resolve_units",
    "detect_units",
    "axis_permutation",
]

#: The six BVH channel names, in their usual spelling.
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CHANNEL_LOOKUP = {c.lower(): c for c in CHANNEL_NAMES}

#: Metres per unit of the CMU database's BVH files as converted by cgspeed:
#: ``(1 / 0.45) * 2.54 / 100`` (the ASF/AMC "length" 0.45 in inches), about 5.64 cm.
CMU_UNIT = 2.54 / 45.0

#: Metres per file unit for the unit names the reader and writer accept.
UNIT_SCALES: dict[str, float] = {
    "m": 1.0,
    "dm": 0.1,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "ft": 0.3048,
    "cmu": CMU_UNIT,
}
_UNIT_ALIASES = {
    "metre": "m", "metres": "m", "meter": "m", "meters": "m",
    "centimetre": "cm", "centimetres": "cm", "centimeter": "cm", "centimeters": "cm",
    "millimetre": "mm", "millimetres": "mm", "millimeter": "mm", "millimeters": "mm",
    "in": "inch", "inches": "inch", "foot": "ft", "feet": "ft",
}

#: Largest magnitude accepted for any number in a BVH file (offsets, positions,
#: angles in degrees).  Larger values are corruption, not motion capture, and
#: would overflow in forward kinematics.
MAX_ABS_VALUE = 1e9

#: Bytes of the MOTION block parsed at a time (1 MB: about 30 MB of transient
#: buffers; smaller chunks are no slower, larger ones only cost memory).
CHUNK_BYTES = 1 << 20

_NUMBER_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NUMBER_PREFIX_RE = re.compile(r"[+-]?[0-9]*\.?[0-9]*(?:[eE][+-]?[0-9]*)?")
_MOTION_RE = re.compile(rb"(?im)^[ \t]*MOTION[ \t]*\r?$")
_FRAMES_RE = re.compile(r"(?i)^\s*frames\s*:\s*(.*?)\s*$")
_FRAME_TIME_RE = re.compile(r"(?i)^\s*frame\s*time\s*:\s*(.*?)\s*$")
_HEADER_CAP = 32 << 20

# Bytes a well-formed MOTION block consists of; anything else sends a chunk to
# the exact (slow) pass, which accepts or describes it.
_FAST_BYTES = np.zeros(256, dtype=bool)
_FAST_BYTES[list(b"0123456789.+-eE \t\r\n")] = True


# ---------------------------------------------------------------------------
# units and axes


def resolve_units(units: str | float, path: str | os.PathLike | None = None) -> tuple[str, float]:
    """``(name, metres per unit)`` for a unit name (``"cm"``, ``"inch"``, ``"cmu"``...)
    or a number of metres per unit (a float, or a string such as ``"0.01"``)."""
    if isinstance(units, (int, float, np.floating, np.integer)) and not isinstance(units, bool):
        scale = float(units)
    else:
        key = str(units).strip().lower()
        key = _UNIT_ALIASES.get(key, key)
        if key in UNIT_SCALES:
            return key, UNIT_SCALES[key]
        try:
            scale = float(key)
        except ValueError:
            known = ", ".join(UNIT_SCALES)
            raise OptionError(
                f"unknown length unit {units!r}; expected one of {known} or metres per unit "
                "as a number (e.g. 0.01)",
                path=path,
            ) from None
    if not (np.isfinite(scale) and scale > 0):
        raise OptionError(f"units must be a positive number of metres per unit, got {units!r}", path=path)
    for name, value in UNIT_SCALES.items():
        if scale == value:
            return name, value
    return f"{scale:g} m", scale


#: Upper bounds (exclusive) of the rest-pose extent, in file units, for each
#: detected unit; a human is about 1-2.2 m tall or wide.  The bounds are the
#: geometric means between neighbouring units' typical extents (1.7 m,
#: 30 CMU units, 67 inches, 170 cm, 1700 mm).
_DETECT_BOUNDS = (
    (7.0, "m"),
    (45.0, "cmu"),
    (107.0, "inch"),
    (540.0, "cm"),
    (float("inf"), "mm"),
)


def detect_units(extent: float) -> tuple[str, float]:
    """Guess the file unit from the skeleton's size.

    ``extent`` is the largest side of the bounding box of the rest pose (the
    pose the offsets describe, usually a T-pose whose arm span and height are
    both about a body height), in file units.  The guess assumes a human-sized
    skeleton: below 7 it is metres, below 45 CMU units (about 5.6 cm), below
    107 inches, below 540 centimetres, otherwise millimetres.
    """
    for bound, name in _DETECT_BOUNDS:
        if extent < bound:
            return name, UNIT_SCALES[name]
    return "mm", UNIT_SCALES["mm"]  # pragma: no cover (inf bound)


def axis_permutation(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(perm, sign)`` with ``(M v)[i] == sign[i] * v[perm[i]]`` for a signed
    permutation matrix ``M`` (the up-axis matrices are), so axes change exactly."""
    m = np.asarray(matrix, dtype=float)
    perm = np.argmax(np.abs(m), axis=1)
    sign = m[np.arange(3), perm]
    if not np.array_equal(np.abs(m), np.eye(3)[perm]):
        raise ValueError("not a signed permutation matrix")
    return perm, sign


# ---------------------------------------------------------------------------
# hierarchy


@dataclass
class _Joint:
    name: str
    parent: int
    line: int
    end_site: bool = False
    offset: list[float] | None = None
    channels: list[str] | None = None
    children: int = 0


@dataclass
class _Header:
    joints: list[_Joint]
    frames_declared: int
    frames_line: int
    frame_time: float
    data_line: int  # 1-based line number of the first line after "Frame Time:"
    cr_only: bool = False


class _Tokens:
    """Whitespace-separated tokens of the hierarchy text with their line numbers."""

    def __init__(self, text: str, path: Path, first_line: int = 1) -> None:
        self.path = path
        self.toks: list[tuple[str, int]] = []
        for i, line in enumerate(text.split("\n")):
            for tok in line.split():
                # "{" and "}" glued to a word ("Hips{") are split off.
                while tok:
                    if tok[0] in "{}":
                        self.toks.append((tok[0], first_line + i))
                        tok = tok[1:]
                        continue
                    cut = min((k for k in (tok.find("{"), tok.find("}")) if k >= 0), default=-1)
                    if cut < 0:
                        self.toks.append((tok, first_line + i))
                        break
                    self.toks.append((tok[:cut], first_line + i))
                    tok = tok[cut:]
        self.pos = 0
        self.last_line = first_line + text.count("\n")

    def peek(self) -> tuple[str, int] | None:
        return self.toks[self.pos] if self.pos < len(self.toks) else None

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.toks):
            raise InputError(f"file ends early: expected {expected}", path=self.path, line=self.last_line)
        tok = self.toks[self.pos]
        self.pos += 1
        return tok

    def rest_of_line(self, line: int) -> list[str]:
        out = []
        while self.pos < len(self.toks) and self.toks[self.pos][1] == line and self.toks[self.pos][0] not in "{}":
            out.append(self.toks[self.pos][0])
            self.pos += 1
        return out


def _show(tok: str) -> str:
    return repr(tok if len(tok) <= 40 else tok[:37] + "...")


def _parse_number(tok: str, line: int, path: Path, what: str) -> float:
    if not _NUMBER_RE.fullmatch(tok):
        if tok.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise InputError(f"{what} is {tok!r}; expected a finite number", path=path, line=line)
        raise InputError(f"expected a number for {what}, found {_show(tok)}", path=path, line=line)
    value = float(tok)
    if not abs(value) <= MAX_ABS_VALUE:
        raise InputError(
            f"{what} is {tok}, out of range (|value| > {MAX_ABS_VALUE:g}); expected a plausible length",
            path=path,
            line=line,
        )
    return value


def _parse_hierarchy(text: str, path: Path) -> list[_Joint]:
    """Parse ``HIERARCHY`` ... ``MOTION`` into joints in file (pre-)order."""
    toks = _Tokens(text, path)
    first = toks.peek()
    if first is None:
        raise InputError("empty file; expected a BVH file starting with HIERARCHY", path=path, line=1)
    tok, line = toks.next("HIERARCHY")
    if tok.upper() != "HIERARCHY":
        raise InputError(
            f"not a BVH file: expected 'HIERARCHY' at the start, found {_show(tok)}", path=path, line=line
        )
    joints: list[_Joint] = []
    stack: list[int] = []  # indices of the open blocks
    while True:
        item = toks.peek()
        if item is None:
            if stack:
                j = joints[stack[-1]]
                raise InputError(
                    f"unbalanced braces: the file ends inside {_what(j)} opened at line {j.line}; "
                    "expected '}'",
                    path=path,
                    line=toks.last_line,
                )
            raise InputError("missing MOTION section; expected 'MOTION' after the hierarchy", path=path,
                             line=toks.last_line)
        tok, line = toks.next("a keyword")
        key = tok.upper()
        if not stack:
            if key == "MOTION":
                if not joints:
                    raise InputError("the hierarchy has no ROOT joint; expected 'ROOT <name>'",
                                     path=path, line=line)
                return joints
            if key != "ROOT":
                if tok == "}":
                    raise InputError("unbalanced braces: '}' without a matching '{'", path=path, line=line)
                raise InputError(f"expected 'ROOT' or 'MOTION', found {_show(tok)}", path=path, line=line)
            stack.append(_open_joint(toks, joints, -1, line, path, key))
            continue
        cur = joints[stack[-1]]
        if key == "OFFSET":
            if cur.offset is not None:
                raise InputError(f"second OFFSET in {_what(cur)}", path=path, line=line)
            vals = []
            for axis in "XYZ":
                t, ln = toks.next(f"three numbers after OFFSET in {_what(cur)}")
                vals.append(_parse_number(t, ln, path, f"OFFSET {axis} of {_what(cur)}"))
            cur.offset = vals
        elif key == "CHANNELS":
            if cur.channels is not None:
                raise InputError(f"second CHANNELS in {_what(cur)}", path=path, line=line)
            t, ln = toks.next("the number of channels after CHANNELS")
            if not re.fullmatch(r"[0-9]+", t) or int(t) > 6:
                raise InputError(
                    f"expected the number of channels (0 to 6) after CHANNELS, found {_show(t)}",
                    path=path,
                    line=ln,
                )
            n = int(t)
            chans: list[str] = []
            for _ in range(n):
                t, ln = toks.next(f"{n} channel names after 'CHANNELS {n}'")
                name = _CHANNEL_LOOKUP.get(t.lower())
                if name is None:
                    raise InputError(
                        f"unknown channel {_show(t)} in {_what(cur)}; expected {n} of "
                        + ", ".join(CHANNEL_NAMES),
                        path=path,
                        line=ln,
                    )
                if name in chans:
                    raise InputError(f"channel {name} listed twice in {_what(cur)}", path=path, line=ln)
                chans.append(name)
            if cur.end_site and chans:
                raise InputError(f"{_what(cur)} has channels; expected none in an End Site",
                                 path=path, line=line)
            cur.channels = chans
        elif key in ("JOINT", "END", "ENDSITE") and not cur.end_site and (cur.offset is None or cur.channels is None):
            missing = "OFFSET" if cur.offset is None else "CHANNELS"
            expect = "'OFFSET x y z'" if cur.offset is None else "'CHANNELS n ...'"
            raise InputError(
                f"{_what(cur)} (line {cur.line}) has no {missing} before its children; expected {expect}",
                path=path,
                line=line,
            )
        elif key == "JOINT":
            if cur.end_site:
                raise InputError(f"JOINT inside {_what(cur)}; expected 'OFFSET' or '}}'", path=path, line=line)
            cur.children += 1
            stack.append(_open_joint(toks, joints, stack[-1], line, path, key, len(stack)))
        elif key in ("END", "ENDSITE"):
            if cur.end_site:
                raise InputError(f"End Site inside {_what(cur)}; expected 'OFFSET' or '}}'", path=path, line=line)
            if key == "END":
                t, ln = toks.next("'Site' after 'End'")
                if t.upper() != "SITE":
                    raise InputError(f"expected 'End Site', found 'End {_show(t)[1:-1]}'", path=path, line=ln)
            toks.rest_of_line(line)  # an optional name some exporters add; unused
            t, ln = toks.next("'{' after End Site")
            if t != "{":
                raise InputError(f"expected '{{' after End Site, found {_show(t)}", path=path, line=ln)
            cur.children += 1
            _check_size(joints, len(stack), line, path)
            joints.append(_Joint(name="", parent=stack[-1], line=line, end_site=True))
            stack.append(len(joints) - 1)
        elif tok == "}":
            if cur.offset is None:
                raise InputError(f"{_what(cur)} (line {cur.line}) has no OFFSET; expected 'OFFSET x y z'",
                                 path=path, line=line)
            if cur.channels is None:
                if not cur.end_site:
                    raise InputError(f"{_what(cur)} (line {cur.line}) has no CHANNELS; expected "
                                     "'CHANNELS n ...'", path=path, line=line)
                cur.channels = []
            stack.pop()
        elif tok == "{":
            raise InputError(f"unbalanced braces: unexpected '{{' in {_what(cur)}", path=path, line=line)
        elif key == "MOTION":
            raise InputError(
                f"unbalanced braces: MOTION inside {_what(cur)} opened at line {cur.line}; expected '}}'",
                path=path,
                line=line,
            )
        else:
            expect = "'OFFSET' or '}'" if cur.end_site else "OFFSET, CHANNELS, JOINT, End Site or '}'"
            raise InputError(f"unexpected {_show(tok)} in {_what(cur)}; expected {expect}", path=path, line=line)


def _what(j: _Joint) -> str:
    return "an End Site" if j.end_site else f"joint {j.name!r}"


def _check_size(joints: list[_Joint], depth: int, line: int, path: Path) -> None:
    """Refuse a hierarchy past :data:`~physmocap.motion.MAX_JOINTS` joints or
    :data:`~physmocap.motion.MAX_DEPTH` levels as soon as the parser reaches it (a
    20,000-deep chain would otherwise cost quadratic time and gigabytes downstream)."""
    from ..motion import MAX_DEPTH, MAX_JOINTS

    if len(joints) >= MAX_JOINTS:
        raise InputError(
            f"more than {MAX_JOINTS} joints (end sites included); physmocap reads skeletons of at most "
            f"{MAX_JOINTS}",
            path=path,
            line=line,
        )
    if depth >= MAX_DEPTH:
        raise InputError(
            f"joints nested more than {MAX_DEPTH} levels deep; physmocap reads chains of at most {MAX_DEPTH}",
            path=path,
            line=line,
        )


def _open_joint(toks: _Tokens, joints: list[_Joint], parent: int, line: int, path: Path, key: str,
                depth: int = 0) -> int:
    _check_size(joints, depth, line, path)
    words = toks.rest_of_line(line)
    if not words:
        raise InputError(f"expected a joint name after {key}", path=path, line=line)
    t, ln = toks.next(f"'{{' after {key} {' '.join(words)}")
    if t != "{":
        raise InputError(f"expected '{{' after {key} {' '.join(words)}, found {_show(t)}", path=path, line=ln)
    joints.append(_Joint(name=" ".join(words), parent=parent, line=line))
    return len(joints) - 1


def _name_joints(joints: list[_Joint], path: Path) -> list[str]:
    """Final joint names: duplicates made unique (with a warning), end sites named."""
    names: list[str] = []
    taken: set[str] = set()
    for j in joints:
        if j.end_site:
            continue
        name = j.name
        if name in taken:
            k = 2
            while f"{name}_{k}" in taken:
                k += 1
            warn(f"{path}:{j.line}: joint name {name!r} is used twice; renamed it {name}_{k}")
            name = f"{name}_{k}"
            j.name = name
        taken.add(name)
    all_joint_names = {j.name for j in joints if not j.end_site}
    used: set[str] = set()
    count: dict[int, int] = {}
    for j in joints:
        if not j.end_site:
            names.append(j.name)
            continue
        parent = joints[j.parent].name
        k = count.get(j.parent, 0)
        while True:
            k += 1
            cand = f"{parent}_End" if k == 1 else f"{parent}_End{k}"
            if cand not in all_joint_names and cand not in used:
                break
        count[j.parent] = k
        used.add(cand)
        j.name = cand
        names.append(cand)
    return names


# ---------------------------------------------------------------------------
# file access


def _read_header(fh, path: Path) -> tuple[_Header, bytes]:
    """Parse everything up to the first motion row; return it and the bytes
    already read past it (the start of the motion rows)."""
    buf = fh.read(1 << 20)
    if not buf:
        raise InputError("empty file; expected a BVH file starting with HIERARCHY", path=path)
    if buf.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputError("UTF-16 text; expected a UTF-8 or ASCII BVH file (re-save it as UTF-8)", path=path,
                         line=1)
    bom = 3 if buf.startswith(b"\xef\xbb\xbf") else 0
    cr_only = b"\n" not in buf[:65536] and b"\r" in buf[:65536]
    if cr_only:
        buf = buf.replace(b"\r", b"\n")
    match = _MOTION_RE.search(buf)
    while match is None and len(buf) < _HEADER_CAP:
        more = fh.read(1 << 20)
        if not more:
            break
        buf += more.replace(b"\r", b"\n") if cr_only else more
        match = _MOTION_RE.search(buf, max(0, len(buf) - len(more) - 64))
    head_end = match.end() if match is not None else len(buf)
    head = buf[:head_end]
    nul = head.find(b"\x00")
    if nul >= 0:
        raise InputError(
            "binary file (contains NUL bytes); expected a BVH text file",
            path=path,
            line=head.count(b"\n", 0, nul) + 1,
        )
    text = _decode(head[bom:], path, 1)
    joints = _parse_hierarchy(text, path)  # raises when MOTION is missing

    # "Frames:" and "Frame Time:" lines after MOTION.
    feed = _LineFeed(fh, buf[head_end:], cr_only)
    line = head.count(b"\n") + 1  # line of MOTION
    feed.next()  # the rest of the MOTION line (its line ending)
    found: dict[str, tuple[str, int]] = {}
    while len(found) < 2:
        raw = feed.next()
        if raw is None:
            break
        line += 1
        txt = _decode(raw, path, line).strip()
        if not txt:
            continue
        m_frames = _FRAMES_RE.match(txt)
        m_time = _FRAME_TIME_RE.match(txt)
        if m_time is not None and "time" not in found:
            found["time"] = (m_time.group(1), line)
        elif m_frames is not None and "frames" not in found:
            found["frames"] = (m_frames.group(1), line)
        else:
            want = " and ".join(
                w for k, w in (("frames", "'Frames: <count>'"), ("time", "'Frame Time: <seconds>'"))
                if k not in found
            )
            raise InputError(f"expected {want} after MOTION, found {_show(txt)}", path=path, line=line)
    for key, what in (("frames", "'Frames: <count>'"), ("time", "'Frame Time: <seconds>'")):
        if key not in found:
            raise InputError(f"file ends early: expected {what} after MOTION", path=path, line=line)
    frames_txt, frames_line = found["frames"]
    if not re.fullmatch(r"\+?[0-9]+", frames_txt):
        raise InputError(f"expected a whole number of frames after 'Frames:', found {_show(frames_txt)}",
                         path=path, line=frames_line)
    time_txt, time_line = found["time"]
    if not _NUMBER_RE.fullmatch(time_txt):
        raise InputError(f"expected a number of seconds after 'Frame Time:', found {_show(time_txt)}",
                         path=path, line=time_line)
    frame_time = float(time_txt)
    if not (frame_time > 0 and np.isfinite(1.0 / frame_time) and frame_time < 1e6):
        raise InputError(f"Frame Time is {time_txt}; expected a positive number of seconds per frame",
                         path=path, line=time_line)
    header = _Header(
        joints=joints,
        frames_declared=int(frames_txt),
        frames_line=frames_line,
        frame_time=frame_time,
        data_line=line + 1,
        cr_only=cr_only,
    )
    return header, feed.remainder()


class _LineFeed:
    """Lines (without their ``\\n``) from bytes already read, then from the file."""

    def __init__(self, fh, buf: bytes, cr_only: bool) -> None:
        self.fh, self.buf, self.pos, self.cr_only = fh, buf, 0, cr_only

    def next(self) -> bytes | None:
        while True:
            nl = self.buf.find(b"\n", self.pos)
            if nl >= 0:
                out = self.buf[self.pos : nl]
                self.pos = nl + 1
                return out
            more = self.fh.read(1 << 16)
            if not more:
                if self.pos < len(self.buf):
                    out = self.buf[self.pos :]
                    self.pos = len(self.buf)
                    return out
                return None
            self.buf = self.buf[self.pos :] + (more.replace(b"\r", b"\n") if self.cr_only else more)
            self.pos = 0

    def remainder(self) -> bytes:
        return self.buf[self.pos :]


def _decode(raw: bytes, path: Path, first_line: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = first_line + raw.count(b"\n", 0, exc.start)
        bad = raw[exc.start : exc.start + 1].hex()
        raise InputError(
            f"not UTF-8 text (byte 0x{bad} cannot be decoded); expected a UTF-8 or ASCII BVH file",
            path=path,
            line=line,
        ) from None


# ---------------------------------------------------------------------------
# motion rows


class _RowError(Exception):
    """A short last row that may be a truncated file (decided by the caller)."""

    def __init__(self, line: int, count: int) -> None:
        self.line = line
        self.count = count


@dataclass
class _Layout:
    """Where each joint's channels sit in a motion row."""

    num_channels: int
    labels: list[str]  # "<joint> <channel>" per column, for messages
    rot_groups: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]  # (order, joints, cols, mask)
    still: np.ndarray  # joints without rotation channels
    pos_joints: np.ndarray  # (K,) joints with position channels
    pos_cols: np.ndarray  # (K, 3) column of each component, -1 if not animated


def _layout(joints: list[_Joint]) -> _Layout:
    col = 0
    labels: list[str] = []
    groups: dict[str, list[tuple[int, list[int]]]] = {}
    still: list[int] = []
    pos_joints: list[int] = []
    pos_cols: list[list[int]] = []
    for j, joint in enumerate(joints):
        chans = joint.channels or []
        rot_axes: list[str] = []
        rot_cols: list[int] = []
        pcols = [-1, -1, -1]
        for c in chans:
            labels.append(f"{joint.name} {c}")
            if c.endswith("rotation"):
                rot_axes.append(c[0])
                rot_cols.append(col)
            else:
                pcols["XYZ".index(c[0])] = col
            col += 1
        if rot_axes:
            order = "".join(rot_axes) + "".join(a for a in "XYZ" if a not in rot_axes)
            groups.setdefault(order, []).append((j, rot_cols + [-1] * (3 - len(rot_cols))))
        else:
            still.append(j)
        if any(c >= 0 for c in pcols):
            pos_joints.append(j)
            pos_cols.append(pcols)
    rot_groups = []
    for order, members in groups.items():
        idx = np.array([m[0] for m in members], dtype=np.int64)
        cols = np.array([m[1] for m in members], dtype=np.int64)
        rot_groups.append((order, idx, np.maximum(cols, 0), cols >= 0))
    return _Layout(
        num_channels=col,
        labels=labels,
        rot_groups=rot_groups,
        still=np.array(still, dtype=np.int64),
        pos_joints=np.array(pos_joints, dtype=np.int64),
        pos_cols=np.array(pos_cols, dtype=np.int64).reshape(-1, 3),
    )


def _parse_chunk_fast(chunk: bytes, C: int) -> np.ndarray | None:
    """Rows of ``chunk`` as an ``(n, C)`` array, or None if anything is unusual."""
    if not _FAST_BYTES[np.frombuffer(chunk, dtype=np.uint8)].all():
        return None
    try:
        values = np.loadtxt(io.BytesIO(chunk), dtype=float, comments=None, ndmin=2)
    except (ValueError, UnicodeError):
        return None
    if values.shape[1] != C:
        return None
    if not np.abs(values).max(initial=0.0) <= MAX_ABS_VALUE:  # also false for NaN
        return None
    return values


def _parse_chunk_exact(
    chunk: bytes, C: int, first_line: int, path: Path, labels: list[str], first_frame: int
) -> tuple[np.ndarray, _RowError | None]:
    """Rows of ``chunk``, checked token by token; raise InputError at the first
    problem.  A short *last* row is returned as a :class:`_RowError` instead."""
    rows: list[list[float]] = []
    lines = chunk.split(b"\n")
    last_nonempty = max((i for i, ln in enumerate(lines) if ln.split()), default=-1)
    pending: _RowError | None = None
    for i, raw in enumerate(lines):
        toks = raw.split()
        if not toks:
            continue
        line = first_line + i
        frame = first_frame + len(rows)
        cut_short = len(toks) < C or (
            len(toks) == C and i == len(lines) - 1 and not _NUMBER_RE.fullmatch(toks[-1].decode("ascii", "replace"))
        )
        if cut_short and i == last_nonempty:
            # Possibly a file cut short: the last token may be cut too.
            _check_tokens(toks[:-1], line, path, labels, frame)
            last = toks[-1].decode("ascii", errors="replace")
            if not _NUMBER_PREFIX_RE.fullmatch(last):
                _check_tokens(toks, line, path, labels, frame)  # raises
            pending = _RowError(line, len(toks))
            break
        if len(toks) != C:
            raise InputError(
                f"expected {C} numbers (one per channel), found {len(toks)}",
                path=path,
                line=line,
                frame=frame,
            )
        rows.append(_check_tokens(toks, line, path, labels, frame))
    return np.array(rows, dtype=float).reshape(-1, C), pending


def _check_tokens(toks: list[bytes], line: int, path: Path, labels: list[str], frame: int) -> list[float]:
    out = []
    for k, tb in enumerate(toks):
        label = labels[k] if k < len(labels) else f"value {k + 1}"
        tok = tb.decode("ascii", errors="replace")
        if not _NUMBER_RE.fullmatch(tok):
            if tok.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                raise InputError(
                    f"{label} (value {k + 1}) is {tok!r}; expected a finite number",
                    path=path,
                    line=line,
                    frame=frame,
                )
            raise InputError(
                f"expected a number for {label} (value {k + 1}), found {_show(tok)}",
                path=path,
                line=line,
                frame=frame,
            )
        v = float(tok)
        if not abs(v) <= MAX_ABS_VALUE:
            raise InputError(
                f"{label} (value {k + 1}) is {tok}, out of range "
                f"(|value| > {MAX_ABS_VALUE:g})",
                path=path,
                line=line,
                frame=frame,
            )
        out.append(v)
    return out


#: Clips with more joint-frames than this (about 15 minutes at 120 Hz with 38
#: joints) are stored as float32: a one-hour clip then needs about 300 MB instead
#: of 600 MB (float32 quaternions keep positions to about 1e-7 of the skeleton's size).
LONG_CLIP_JOINT_FRAMES = 4_000_000


class _Store:
    """Growing output arrays: rotations (F, J, 4) in world axes and
    translations (F, K, 3) in world axes and *file* units.  A long clip's are
    kept in temporary files (:mod:`physmocap.spill`), each chunk's pages let go
    once written."""

    def __init__(self, capacity: int, J: int, K: int, dtype=np.float64) -> None:
        self.rot = spilled_empty((capacity, J, 4), dtype=dtype)
        self.tra = spilled_empty((capacity, K, 3), dtype=dtype)
        self.n = 0
        self.extra: list[tuple[np.ndarray, np.ndarray]] = []

    def put(self, rot: np.ndarray, tra: np.ndarray) -> None:
        n = rot.shape[0]
        room = max(0, self.rot.shape[0] - self.n)
        k = min(n, room)
        if k:
            self.rot[self.n : self.n + k] = rot[:k]
            self.tra[self.n : self.n + k] = tra[:k]
            release(self.rot)
            release(self.tra)
        if k < n:
            self.extra.append((rot[k:].copy(), tra[k:].copy()))
        self.n += n

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if self.extra:
            rot = np.concatenate([self.rot] + [e[0] for e in self.extra])
            tra = np.concatenate([self.tra] + [e[1] for e in self.extra])
            return rot, tra
        if self.n < self.rot.shape[0]:
            # Copy (rather than keep a view of) an array that was allocated too large.
            return self.rot[: self.n].copy(), self.tra[: self.n].copy()
        return self.rot, self.tra


def _convert(values: np.ndarray, lay: _Layout, offsets: np.ndarray, J: int,
             perm: np.ndarray, sign: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Channel rows ``(n, C)`` to local rotations ``(n, J, 4)`` and translations
    ``(n, K, 3)`` (file units), both in world (Z-up) axes."""
    n = values.shape[0]
    rot = np.empty((n, J, 4))
    for order, idx, cols, mask in lay.rot_groups:
        angles = values[:, cols]
        if not mask.all():
            angles = angles * mask
        rot[:, idx] = euler_to_quat(angles, order, degrees=True)
    if lay.still.size:
        rot[:, lay.still, :3] = 0.0
        rot[:, lay.still, 3] = 1.0
    # Axis change of the vector part: (M v, w).
    rot[..., :3] = rot[..., perm] * sign
    K = lay.pos_joints.size
    tra = np.empty((n, K, 3))
    if K:
        tra[:] = offsets[lay.pos_joints]
        for a in range(3):
            has = lay.pos_cols[:, a] >= 0
            if has.any():
                tra[:, has, a] = values[:, lay.pos_cols[has, a]]
        tra = tra[..., perm] * sign
    return rot, tra


def _read_rows(fh, header: _Header, lay: _Layout, leftover: bytes, path: Path, size: int,
               J: int, offsets: np.ndarray, perm: np.ndarray, sign: np.ndarray) -> tuple[_Store, _RowError | None]:
    C = lay.num_channels
    consumed = fh.tell() - len(leftover)
    bound = max(0, size - consumed) // (2 * C) + 1
    capacity = min(header.frames_declared, bound)
    dtype = np.float32 if capacity * J > LONG_CLIP_JOINT_FRAMES else np.float64
    store = _Store(capacity, J, lay.pos_joints.size, dtype)
    line = header.data_line
    carry = leftover
    pending: _RowError | None = None
    eof = False
    while not eof:
        block = fh.read(CHUNK_BYTES)
        eof = not block
        if header.cr_only and block:
            block = block.replace(b"\r", b"\n")
        data = carry + block if carry else block
        if eof:
            chunk, carry = data, b""
        else:
            cut = data.rfind(b"\n")
            if cut < 0:
                carry = data
                continue
            chunk, carry = data[: cut + 1], data[cut + 1 :]
        if not chunk.strip():
            line += chunk.count(b"\n")
            continue
        if pending is not None:
            # A short row turned out not to be the last one.
            raise InputError(
                f"expected {C} numbers (one per channel), found {pending.count}",
                path=path,
                line=pending.line,
                frame=store.n,
            )
        values = _parse_chunk_fast(chunk, C)
        if values is None:
            values, pending = _parse_chunk_exact(chunk, C, line, path, lay.labels, store.n)
        rot, tra = _convert(values, lay, offsets, J, perm, sign)
        store.put(rot, tra)
        line += chunk.count(b"\n")
    return store, pending


# ---------------------------------------------------------------------------
# public entry point


#: Frames of the motion sampled to confirm a Z-up file (forward kinematics of each).
_UP_PROBE_FRAMES = 64


def _rest_taller_along_z(offsets_file: np.ndarray, parents: np.ndarray) -> bool:
    """Whether the rest pose (file axes) is much taller along Z than along Y: over twice its
    Y extent and a real part of the figure's size (not a flat or degenerate skeleton)."""
    rest = np.zeros_like(offsets_file)
    for j in range(len(parents)):
        rest[j] = offsets_file[j] if parents[j] < 0 else rest[parents[j]] + offsets_file[j]
    ext = np.ptp(rest, axis=0)
    return bool(ext[2] > 2.0 * max(ext[1], 1e-12) and ext[2] > 0.3 * ext.max())


def _z_up_file(offsets_file: np.ndarray, parents: np.ndarray, end_sites: np.ndarray,
               names: list[str], rotations: np.ndarray, translations: np.ndarray,
               lay: "_Layout") -> bool:
    """Whether a file read as Y-up is a Z-up file: the rest pose is much taller along the
    file's Z than along its Y (:func:`_rest_taller_along_z`), and so is the motion (the
    median over sampled frames of each frame's extent along Z exceeds that along Y).  Both
    must agree: a Y-up file whose rest pose lies along Z (a non-standing reference pose)
    still stands along Y while it moves, and is left Y-up."""
    if len(rotations) == 0 or not _rest_taller_along_z(offsets_file, parents):
        return False
    m = up_axis_matrix("Y", "Z")  # world = m @ file, as the rows were read
    probe = Skeleton(tuple(names), parents, offsets_file @ m.T, end_sites)
    idx = np.unique(np.linspace(0, len(rotations) - 1, min(len(rotations), _UP_PROBE_FRAMES)).astype(int))
    pos, _ = forward_kinematics(probe, rotations[idx], translations[idx], lay.pos_joints, with_rotations=False)
    # Each frame's extent over the joints between their 5th and 95th percentiles along each
    # axis (world Z = file Y, world Y = -file Z): a root wrapper left at the origin while the
    # body walks away (Bandai Namco's joint_Root) is not part of the figure's size
    # ("nearest": a skeleton of 14 points still drops its outermost one at each end).
    ext = np.percentile(pos, 95.0, axis=1, method="nearest") - np.percentile(pos, 5.0, axis=1, method="nearest")
    return bool(np.median(ext[:, 1]) > np.median(ext[:, 2]))


def read_bvh(
    path: str | os.PathLike,
    units: str | float | None = None,
    up: str | None = None,
) -> Motion:
    """Read a BVH file into a rotational :class:`~physmocap.motion.Motion`.

    Args:
        path: The ``.bvh`` file.
        units: The file's length unit: a name (``"m"``, ``"cm"``, ``"mm"``,
            ``"inch"``, ``"ft"``, ``"cmu"``) or metres per file unit as a
            number.  ``None`` detects it from the rest pose (:func:`detect_units`).
        up: The file's up axis, ``"Y"`` (the BVH convention) or ``"Z"``; ``None`` reads it as
            Y-up unless the rest pose and the motion both stand along Z (:func:`_z_up_file`).

    Returns:
        The motion in metres, Z-up, with x-y-z-w local rotations.  ``meta``
        records the file's channel layout (``bvh_channels``: joint name to its
        channel list, ``bvh_rotation_orders``: joint name to the axes of its
        rotation channels in file order), ``frame_time``, ``frames_declared``,
        ``units_detected`` and ``rest_extent`` (the rest-pose extent in file
        units), so :func:`physmocap.export.bvh.write_bvh` can write the same
        layout back.

    Raises:
        InputError: The file is not a well-formed BVH file (the message names
            the file, the line and what was expected).
        OptionError: ``units`` or ``up`` is not understood.
    """
    path = Path(path)
    file_up = "Y" if up is None else str(up).strip().upper()
    if file_up not in ("Y", "Z"):
        raise OptionError(f"up axis must be 'Y' or 'Z', got {up!r}", path=path)
    unit_choice = None if units is None else resolve_units(units, path)
    perm, sign = axis_permutation(up_axis_matrix(file_up, "Z"))

    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a BVH file", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot open: {exc.strerror}", path=path) from None
    with fh:
        size = os.fstat(fh.fileno()).st_size
        header, leftover = _read_header(fh, path)
        joints = header.joints
        names = _name_joints(joints, path)
        J = len(joints)
        lay = _layout(joints)
        C = lay.num_channels
        if C == 0:
            raise InputError("the hierarchy declares no channels; expected CHANNELS on at least one joint",
                             path=path, line=joints[0].line)
        offsets_file = np.array([j.offset for j in joints], dtype=float)
        store, pending = _read_rows(fh, header, lay, leftover, path, size, J, offsets_file, perm, sign)

    rows = store.n
    declared = header.frames_declared
    if pending is not None:
        truncated = " (the file looks truncated)" if declared > rows else ""
        raise InputError(
            f"expected {C} numbers (one per channel), found {pending.count}{truncated}; "
            f"the {rows} complete frames before it can be kept by cutting the file at this line",
            path=path,
            line=pending.line,
            frame=rows,
        )
    elif rows != declared:
        warn(
            f"{path}:{header.frames_line}: 'Frames: {declared}' but the file has {rows} frame rows; "
            f"read the {rows} rows present"
        )
    rotations, translations = store.arrays()
    parents = np.array([j.parent for j in joints], dtype=np.int64)
    end_sites = np.array([j.end_site for j in joints], dtype=bool)
    if up is None and _z_up_file(offsets_file, parents, end_sites, names, rotations, translations, lay):
        # Read as Y-up (world = M file); the file is Z-up: take the rows back to file axes
        # (a quaternion's vector part and a translation both turn by M^T) and keep them.
        m = up_axis_matrix("Y", "Z")
        for a in range(0, rows, 4096):  # a block at a time: a long clip's rows are not copied whole
            rotations[a : a + 4096, :, :3] = rotations[a : a + 4096, :, :3] @ m
            translations[a : a + 4096] = translations[a : a + 4096] @ m
        file_up = "Z"
        perm, sign = axis_permutation(up_axis_matrix(file_up, "Z"))
        warn(f"{path}: the rest pose and the motion are both much taller along Z than along Y: "
             "read it as Z-up (pass up='Y' / --in-up Y to read it as Y-up)")

    # Rest pose in world axes, file units.
    offsets_world = offsets_file[:, perm] * sign
    rest = np.zeros((J, 3))
    for j in range(J):
        rest[j] = offsets_world[j] if parents[j] < 0 else rest[parents[j]] + offsets_world[j]
    extent = float(np.ptp(rest, axis=0).max())
    if extent < 1e-9 and rows:
        # All offsets zero (everything in position channels): size up frame 0.
        probe = Skeleton(tuple(names), parents, offsets_world, np.array([j.end_site for j in joints]))
        pos0, _ = forward_kinematics(probe, rotations[:1], translations[:1], lay.pos_joints)
        extent = float(np.ptp(pos0[0], axis=0).max())
    if unit_choice is None:
        if extent < 1e-9:
            unit_name, scale = "m", 1.0
            warn(f"{path}: the skeleton has no size to detect its units from; assuming metres "
                 "(pass units=... / --in-units to override)")
        else:
            unit_name, scale = detect_units(extent)
    else:
        unit_name, scale = unit_choice
    if up is None and file_up == "Y" and _rest_taller_along_z(offsets_file, parents):
        warn(f"{path}: the rest pose is much taller along Z than along Y (the motion is not); if the "
             "file is Z-up read it with up='Z' (--in-up Z)")

    if scale != 1.0:
        translations *= scale
    channels_meta = {n: list(j.channels or []) for n, j in zip(names, joints) if not j.end_site}
    orders_meta = {
        n: "".join(c[0] for c in (j.channels or []) if c.endswith("rotation"))
        for n, j in zip(names, joints)
        if not j.end_site and any(c.endswith("rotation") for c in (j.channels or []))
    }
    meta = {
        "format": "bvh",
        "bvh_channels": channels_meta,
        "bvh_rotation_orders": orders_meta,
        "frame_time": header.frame_time,
        "frames_declared": declared,
        "units_detected": unit_choice is None,
        "rest_extent": extent,
    }
    try:
        skeleton = Skeleton(
            names=tuple(names),
            parents=parents,
            offsets=offsets_world * scale,
            end_site=np.array([j.end_site for j in joints], dtype=bool),
        )
        return Motion(
            skeleton=skeleton,
            fps=1.0 / header.frame_time,
            rotations=rotations,
            translations=translations,
            translated=lay.pos_joints,
            source=str(path),
            units=unit_name,
            unit_scale=scale,
            file_up=file_up,
            meta=meta,
        )
    except ValueError as exc:  # should not happen after the checks above
        raise InputError(f"cannot build a motion: {exc}", path=path) from None
