"""Character mapping files (TOML): which site or body of an MJCF is which canonical joint.

A mapping file sits beside its model as ``<stem>.map.toml``
(``physmocap character init MODEL.xml`` proposes one, :mod:`physmocap.models.propose`).
Every table is optional except ``[joints]``; a character must map the pelvis, hips,
knees and ankles; the neck, wrists and arms are optional (an arm is its shoulder and elbow,
both or neither; a robot without arms leaves them out)::

    [character]
    name = "robot"            # default: the MJCF file's stem
    up = "Z"                  # the model's up axis in its own frame: X, Y, Z, -X, -Y, -Z
    forward = "X"             # the direction the model faces in its own frame
    require_limits = true     # every hinge/slide must have a range (or a list of joint names)
    range_policy = "default"  # default humanoid only: "default" or "strict" (physmocap.models.rom)

    [joints]                  # canonical joint = "site:NAME" | "body:NAME" | "NAME"
    pelvis = "site:pelvis_site"   # a bare NAME is a site if one has that name, else a body
    left_knee = "body:l_shank"

    [contacts]                # foot contact SITES, heel to toe (optional: without it the heel
    left = ["l_heel", "l_toe"]  # and toe are found on the feet's geometry, physmocap.models.footprint)
    right = ["r_heel", "r_toe"]

    [sites]                   # sites to add to the model before it is compiled (MjSpec), for
    neck = { body = "torso_link", pos = [0.0, 0.0, 0.35] }   # points a stock model lacks

    [rest]                    # the rest pose: standing, arms down, facing forward
    keyframe = "home"         # start from this keyframe (default: "rest" if present, else qpos0)
    [rest.joints]             # then set these joints (degrees for hinges, metres for slides)
    l_knee = 0.0

    [velocity_limits]         # degrees/s (hinges) or m/s (slides); "default" for the rest
    default = 600
    l_knee = 900

    [joint_limits]            # override or add ranges: [lo, hi] degrees (hinges) / metres (slides)
    l_knee = [-5, 150]

Errors name the mapping file, the line of the entry and what is wrong
(:class:`physmocap.errors.MappingError`).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from ..canonical import CANONICAL_NAMES
from ..errors import MappingError
from ..fileio import read_toml

__all__ = ["TrackedFrame", "Mapping", "read_mapping", "mapping_from_text", "implicit_mapping", "AXES"]

#: Axis names accepted for ``up`` and ``forward``.
AXES = {
    "X": (1.0, 0.0, 0.0),
    "Y": (0.0, 1.0, 0.0),
    "Z": (0.0, 0.0, 1.0),
    "-X": (-1.0, 0.0, 0.0),
    "-Y": (0.0, -1.0, 0.0),
    "-Z": (0.0, 0.0, -1.0),
}
_AXES_PLUS = {"+" + k: v for k, v in AXES.items() if not k.startswith("-")}

#: Contact site names looked for when a model has no mapping file.
IMPLICIT_CONTACTS = ("heel", "ball", "toe_tip")


@dataclass(frozen=True)
class TrackedFrame:
    """A canonical joint's frame on the character: a site or a body, by name.

    The one place that knows how to find it in a model: :meth:`object_id`,
    :meth:`body_id`, :meth:`position`, :meth:`rotation`.
    """

    kind: str  # "site" or "body"
    name: str

    def object_id(self, model: mujoco.MjModel) -> int:
        """The site's id (a site) or the body's id (a body) in ``model``."""
        return int(model.site(self.name).id if self.kind == "site" else model.body(self.name).id)

    def body_id(self, model: mujoco.MjModel) -> int:
        """The id of the body that carries the frame (a site's body, or the body itself)."""
        return int(model.site(self.name).bodyid[0] if self.kind == "site" else model.body(self.name).id)

    def position(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """``(3,)`` its world position in ``data`` after kinematics (metres; a view: copy to keep)."""
        i = self.object_id(model)
        return data.site_xpos[i] if self.kind == "site" else data.xpos[i]

    def rotation(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """``(3, 3)`` its world rotation matrix in ``data`` after kinematics (a view: copy to keep)."""
        i = self.object_id(model)
        return (data.site_xmat[i] if self.kind == "site" else data.xmat[i]).reshape(3, 3)


@dataclass
class Mapping:
    """The contents of a mapping file, checked against its model."""

    path: Path | None
    name: str | None = None
    up: str = "Z"
    forward: str = "X"
    require_limits: bool | tuple[str, ...] = False
    range_policy: str | None = None
    joints: dict[str, TrackedFrame] = field(default_factory=dict)
    contacts: dict[str, tuple[str, ...]] = field(default_factory=dict)
    rest_keyframe: str | None = None
    rest_joints: dict[str, float] = field(default_factory=dict)
    velocity_limits: dict[str, float] = field(default_factory=dict)  # deg/s or m/s, "default" allowed
    joint_limits: dict[str, tuple[float, float]] = field(default_factory=dict)  # deg or m
    sites: dict[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)  # name -> (body, pos m)
    text: str = ""

    def line_of(self, section: str, key: str | None = None) -> int | None:
        """1-based line of ``key`` in ``[section]`` of the file (or of the section header)."""
        return _line_of(self.text, section, key)

    def error(self, message: str, section: str, key: str | None = None) -> MappingError:
        """A :class:`MappingError` naming this file and the entry's line."""
        entry = f"[{section}]" + (f" {key}" if key is not None else "")
        return MappingError(f"{entry}: {message}", path=self.path, line=self.line_of(section, key))


def _line_of(text: str, section: str, key: str | None) -> int | None:
    current = None
    header = re.compile(r"^\s*\[\s*([^\]]+?)\s*\]\s*(#.*)?$")
    for i, line in enumerate(text.splitlines(), 1):
        m = header.match(line)
        if m:
            current = m.group(1).strip()
            if key is None and current == section:
                return i
            continue
        if key is not None and current == section:
            stripped = line.strip()
            for quoted in (key, f'"{key}"', f"'{key}'"):
                if re.match(re.escape(quoted) + r"\s*=", stripped):
                    return i
    return None


def _axis(mapping: Mapping, key: str, value: object) -> str:
    if not isinstance(value, str) or value.upper() not in {**AXES, **_AXES_PLUS}:
        raise mapping.error(
            f"expected one of {', '.join(AXES)}, got {value!r}", "character", key
        )
    v = value.upper()
    return v[1:] if v.startswith("+") else v


def _number(mapping: Mapping, section: str, key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise mapping.error(f"expected a number, got {value!r}", section, key)
    x = float(value)
    if x != x or x in (float("inf"), float("-inf")):
        raise mapping.error(f"expected a finite number, got {value!r}", section, key)
    return x


def read_mapping(path: str | os.PathLike) -> Mapping:
    """Parse a mapping file's syntax and types (not yet checked against a model)."""
    p = Path(path)
    raw, text = read_toml(p, "mapping file")
    return _parse_mapping(raw, text, p)


def mapping_from_text(text: str, path: str | os.PathLike) -> Mapping:
    """Parse mapping TOML held in memory (e.g. a proposed mapping); ``path`` names it in
    messages."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    p = Path(path)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MappingError(f"not valid TOML: {exc}", path=p) from None
    return _parse_mapping(raw, text, p)


def _parse_mapping(raw: dict, text: str, p: Path) -> Mapping:
    mp = Mapping(path=p, text=text)
    known = {"character", "joints", "contacts", "rest", "velocity_limits", "joint_limits", "sites"}
    for key in raw:
        if key not in known:
            raise MappingError(
                f"unknown table [{key}]; expected {', '.join(sorted(known))}",
                path=p,
                line=_line_of(text, key, None),
            )

    char = raw.get("character", {})
    if not isinstance(char, dict):
        raise mp.error("expected a table", "character")
    for key, value in char.items():
        if key == "name":
            if not isinstance(value, str) or not value:
                raise mp.error("expected a non-empty string", "character", key)
            mp.name = value
        elif key == "up":
            mp.up = _axis(mp, key, value)
        elif key == "forward":
            mp.forward = _axis(mp, key, value)
        elif key == "require_limits":
            if isinstance(value, bool):
                mp.require_limits = value
            elif isinstance(value, list) and all(isinstance(v, str) for v in value):
                mp.require_limits = tuple(value)
            else:
                raise mp.error("expected true, false or a list of joint names", "character", key)
        elif key == "range_policy":
            if value not in ("default", "strict"):
                raise mp.error(f"expected \"default\" or \"strict\", got {value!r}", "character", key)
            mp.range_policy = value
        else:
            raise mp.error(
                "unknown key; expected name, up, forward, require_limits, range_policy",
                "character",
                key,
            )
    if AXES[mp.up] == AXES[mp.forward] or AXES[mp.up] == tuple(-x for x in AXES[mp.forward]):
        raise mp.error(f"forward {mp.forward!r} is parallel to up {mp.up!r}", "character", "forward")

    joints = raw.get("joints")
    if not isinstance(joints, dict):
        raise MappingError("missing [joints] table (canonical joint = \"site:NAME\" or \"body:NAME\")", path=p)
    for canon, value in joints.items():
        if canon not in CANONICAL_NAMES:
            raise mp.error(
                f"not a canonical joint; expected one of {', '.join(CANONICAL_NAMES)}", "joints", canon
            )
        if isinstance(value, dict) and len(value) == 1:
            ((kind, name),) = value.items()
        elif isinstance(value, str):
            kind, _, name = value.rpartition(":")
            kind = kind or "auto"
        else:
            raise mp.error(f"expected \"site:NAME\", \"body:NAME\" or \"NAME\", got {value!r}", "joints", canon)
        if kind not in ("site", "body", "auto") or not isinstance(name, str) or not name:
            raise mp.error(f"expected \"site:NAME\", \"body:NAME\" or \"NAME\", got {value!r}", "joints", canon)
        other = next((c for c, tf in mp.joints.items() if (tf.kind, tf.name) == (kind, name)), None)
        if other is not None:
            raise mp.error(f"{value!r} is already the frame of {other}; each canonical joint needs its own",
                           "joints", canon)
        mp.joints[canon] = TrackedFrame(kind, name)

    contacts = raw.get("contacts", {})
    if not isinstance(contacts, dict):
        raise mp.error("expected a table", "contacts")
    for side, sites in contacts.items():
        if side not in ("left", "right"):
            raise mp.error("expected left or right", "contacts", side)
        if not isinstance(sites, list) or not sites or not all(isinstance(s, str) for s in sites):
            raise mp.error("expected a non-empty list of site names", "contacts", side)
        for i, site in enumerate(sites):  # a repeated site would be a repeated row in the IK's QP
            if site in sites[:i]:
                raise mp.error(f"site {site!r} is listed more than once", "contacts", side)
            other = next((o for o, ss in mp.contacts.items() if site in ss), None)
            if other is not None:
                raise mp.error(f"site {site!r} is already a contact of the {other} foot", "contacts", side)
        mp.contacts[side] = tuple(sites)

    added = raw.get("sites", {})
    if not isinstance(added, dict):
        raise mp.error("expected a table", "sites")
    for name, spec in added.items():
        ok = isinstance(spec, dict) and isinstance(spec.get("body"), str) and set(spec) <= {"body", "pos"}
        pos = spec.get("pos", [0.0, 0.0, 0.0]) if isinstance(spec, dict) else None
        if not ok or not isinstance(pos, list) or len(pos) != 3 or not all(isinstance(v, (int, float)) for v in pos):
            raise mp.error('expected { body = "BODY", pos = [x, y, z] } (metres, in the body\'s frame)', "sites", name)
        if not all(abs(float(v)) < 100.0 for v in pos):
            raise mp.error("pos must be within 100 m of the body", "sites", name)
        mp.sites[name] = (spec["body"], (float(pos[0]), float(pos[1]), float(pos[2])))

    rest = raw.get("rest", {})
    if not isinstance(rest, dict):
        raise mp.error("expected a table", "rest")
    for key, value in rest.items():
        if key == "keyframe":
            if not isinstance(value, str):
                raise mp.error("expected a keyframe name", "rest", key)
            mp.rest_keyframe = value
        elif key == "joints":
            if not isinstance(value, dict):
                raise mp.error("expected a table of joint = value", "rest", key)
            for jn, x in value.items():
                mp.rest_joints[jn] = _number(mp, "rest.joints", jn, x)
        else:
            raise mp.error("unknown key; expected keyframe or [rest.joints]", "rest", key)

    vel = raw.get("velocity_limits", {})
    if not isinstance(vel, dict):
        raise mp.error("expected a table", "velocity_limits")
    for jn, x in vel.items():
        v = _number(mp, "velocity_limits", jn, x)
        if v <= 0:
            raise mp.error(f"expected a positive speed, got {x!r}", "velocity_limits", jn)
        mp.velocity_limits[jn] = v

    lim = raw.get("joint_limits", {})
    if not isinstance(lim, dict):
        raise mp.error("expected a table", "joint_limits")
    for jn, pair in lim.items():
        if not isinstance(pair, list) or len(pair) != 2:
            raise mp.error(f"expected [lo, hi], got {pair!r}", "joint_limits", jn)
        lo = _number(mp, "joint_limits", jn, pair[0])
        hi = _number(mp, "joint_limits", jn, pair[1])
        if not lo < hi:
            raise mp.error(f"expected lo < hi, got [{lo:g}, {hi:g}]", "joint_limits", jn)
        mp.joint_limits[jn] = (lo, hi)
    return mp


def implicit_mapping(model: mujoco.MjModel) -> Mapping:
    """The mapping of a model without a mapping file: sites named like canonical joints.

    Contacts are the sites ``<side>_heel``, ``<side>_ball`` and ``<side>_toe_tip``
    that exist.  This is how the default humanoid and its scaled copies map.
    """
    mp = Mapping(path=None)
    sites = {model.site(i).name for i in range(model.nsite)}
    for canon in CANONICAL_NAMES:
        if canon in sites:
            mp.joints[canon] = TrackedFrame("site", canon)
    for side in ("left", "right"):
        names = tuple(f"{side}_{c}" for c in IMPLICIT_CONTACTS if f"{side}_{c}" in sites)
        if names:
            mp.contacts[side] = names
    return mp
