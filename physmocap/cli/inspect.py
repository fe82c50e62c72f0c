"""``physmocap inspect``: what a capture file holds and how it maps to the canonical joints.

Prints the skeleton tree (with each BVH joint's channels and the canonical
joint it maps to), the detected or forced naming profile, the mapping and
what stays unmapped, the frame count, rate and duration, the length unit and
up axis, the standing height and the floor estimate.  ``--json`` prints the
same as one JSON document; ``--emit-map`` prints the mapping as a TOML file
to edit and pass back with ``--map`` (or ``retarget --source-map``).

Everything goes to stdout; warnings and errors to stderr.  A skeleton whose
required canonical joints cannot be mapped is still described, then the
command fails with status 2 and says which joints are missing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from typing import Any

import numpy as np

from ..canonical import CANONICAL_JOINTS, CANONICAL_NAMES, REQUIRED_JOINTS
from ..errors import MappingError, OptionError, warn
from ..resources import display_path

__all__ = ["register", "run", "describe"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "inspect",
        help="describe a capture file: skeleton, profile, canonical mapping, units, floor",
        description=(
            "Describe a capture file: its skeleton tree, the naming profile detected (or forced), "
            "how its joints map to the canonical joints, frames, rate, units, height and floor. "
            "FILE may be 'example' (the bundled CMU walk)."
        ),
    )
    p.add_argument("input", metavar="FILE", help="motion file (.bvh, ...) or 'example'")
    p.add_argument(
        "--profile",
        metavar="P",
        help="force the skeleton naming profile: cmu, optitrack, vicon, mixamo, lafan1, bandai_namco, xsens, "
        "smpl, kinect_v2, ... , topology or none (default: auto; an unknown name lists them all)",
    )
    p.add_argument("--map", metavar="MAP.toml", help="source mapping file (TOML) overriding the profile")
    p.add_argument(
        "--units", "--in-units", dest="units", metavar="U",
        help="the file's length unit: m, dm, cm, mm, inch, ft, cmu (CMU BVH), or metres per unit as a number; default: detect",
    )
    p.add_argument("--up", "--in-up", dest="up", metavar="AXIS", choices=["Y", "Z", "y", "z"],
                   help="the file's up axis (BVH default Y)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print one JSON document instead of text")
    out.add_argument("--emit-markerset", action="store_true",
                     help="marker files: print a marker set TOML (roles -> labels) to edit and pass with --marker-set")
    p.add_argument("--marker-set", metavar="SET.toml", help="marker files: marker set file overriding the built-in aliases")
    out.add_argument("--emit-map", action="store_true",
                     help="print the mapping as a TOML mapping file (edit it, pass it with --map)")
    p.set_defaults(func=run)


def _num(x: float, digits: int = 6) -> float | None:
    x = float(x)
    return round(x, digits) + 0.0 if math.isfinite(x) else None


def describe(motion, jmap) -> dict[str, Any]:
    """The inspection report of ``motion`` mapped by ``jmap`` as JSON-ready data."""
    from ..sources.profiles import PROFILES
    from ..sources.profiles.structure import standing_pose

    skel = motion.skeleton
    channels = motion.meta.get("bvh_channels", {}) if isinstance(motion.meta, dict) else {}
    canon_of = {j: c for c, j in jmap.indices.items()}
    joints = []
    for j, name in enumerate(skel.names):
        p = int(skel.parents[j])
        joints.append(
            {
                "index": j,
                "name": name,
                "parent": None if p < 0 else skel.names[p],
                "end_site": bool(skel.end_site[j]),
                "offset_m": [_num(v) for v in skel.offsets[j]],
                "channels": channels.get(name) if not skel.end_site[j] else None,
                "canonical": canon_of.get(j),
            }
        )
    mapping: dict[str, Any] = {}
    for c in CANONICAL_NAMES:
        if c in jmap.indices:
            mapping[c] = {"source": skel.names[jmap.indices[c]], "index": jmap.indices[c]}
        elif c in jmap.derived:
            mapping[c] = {
                "derived": [{"source": skel.names[i], "weight": _num(w)} for i, w in jmap.derived[c]]
            }
        else:
            mapping[c] = None
    pose, where = standing_pose(motion)
    z = pose[:, 2][np.isfinite(pose[:, 2])]
    height = float(z.max() - z.min()) if z.size else 0.0
    prof = PROFILES.get(jmap.based_on or jmap.profile)
    return {
        "file": display_path(motion.source),  # the bundled clip as "example"
        "format": motion.meta.get("format") if isinstance(motion.meta, dict) else None,
        "kind": "rotational" if motion.is_rotational else "positional",
        "frames": motion.num_frames,
        "fps": _num(motion.fps),
        "duration_s": _num(motion.duration),
        "units": motion.units,
        "unit_scale_m": _num(motion.unit_scale, 9),
        "units_detected": motion.meta.get("units_detected") if isinstance(motion.meta, dict) else None,
        "file_up": motion.file_up,
        "height_m": _num(height),
        "height_pose": where,
        "rest_height_m": _num(skel.height()),
        "floor_m": _num(motion.floor_height()),
        # offset_m (each joint's rest offset from its parent) is in physmocap's world frame,
        # whatever the file's up axis (file_up): say so in the document itself
        "offset_axes": "Z-up",
        "offset_note": "joints[].offset_m: metres, in physmocap's Z-up frame (converted from the file's "
        f"{motion.file_up}-up axes)",
        "num_joints": int(np.count_nonzero(~skel.end_site)),
        "num_end_sites": int(np.count_nonzero(skel.end_site)),
        "joints": joints,
        "profile": jmap.profile,
        "based_on": jmap.based_on,
        "profile_description": prof.description if prof else None,
        "mapping": mapping,
        "unmapped": list(jmap.unmapped),
        "missing_required": list(jmap.missing(REQUIRED_JOINTS)),
        "notes": list(jmap.notes),
    }


def _fmt(x: float | None, spec: str) -> str:
    """A number of the report, or "n/a" where it is not finite (None in the JSON)."""
    return "n/a" if x is None else format(x, spec)


def _text(rep: dict[str, Any]) -> str:
    out: list[str] = []
    add = out.append
    add(f"file:      {rep['file']}" + (f" ({rep['format'].upper()}, {rep['kind']})" if rep["format"] else
                                        f" ({rep['kind']})"))
    add(f"frames:    {rep['frames']} at {_fmt(rep['fps'], '.6g')} fps, {_fmt(rep['duration_s'], '.3f')} s")
    det = "detected" if rep["units_detected"] else "given"
    add(f"units:     {rep['units']} ({_fmt(rep['unit_scale_m'], '.6g')} m per file unit, {det}); "
        f"file up axis {rep['file_up']}")
    add(f"height:    {_fmt(rep['height_m'], '.3f')} m ({rep['height_pose']})"
        + ("" if rep["height_pose"] == "rest pose" else
           f"; the rest pose is not a standing body (rest extent {_fmt(rep['rest_height_m'], '.3f')} m)"))
    add(f"floor:     {_fmt(rep['floor_m'], '.3f')} m (5th percentile of the lowest joint per frame)")
    add(f"skeleton:  {rep['num_joints']} joints, {rep['num_end_sites']} end sites")
    depth: dict[str, int] = {}
    for j in rep["joints"]:
        d = 0 if j["parent"] is None else depth[j["parent"]] + 1
        depth[j["name"]] = d
        label = f"{j['name']} (end site)" if j["end_site"] else j["name"]
        line = "  " + "  " * d + label
        if j["channels"]:
            line += "  [" + " ".join(j["channels"]) + "]"
        if j["canonical"]:
            line += f"  -> {j['canonical']}"
        add(line)
    prof = rep["profile"]
    if rep["based_on"]:
        prof += f" (mapping file, starting from {rep['based_on']})"
    if rep["profile_description"]:
        prof += f": {rep['profile_description']}"
    add(f"profile:   {prof}")
    add("mapping:   canonical joint <- source joint")
    width = max(len(c) for c in CANONICAL_NAMES)
    required = {j.name for j in CANONICAL_JOINTS if j.required}
    for c, m in rep["mapping"].items():
        if m is None:
            continue
        src = m["source"] if "source" in m else (
            "midpoint of " + " and ".join(p["source"] for p in m["derived"])
            if len(m["derived"]) == 2 else
            " + ".join(f"{p['weight']:g} * {p['source']}" for p in m["derived"])
        )
        add(f"  {c:<{width}}  {src}")
    unm = [c + (" (required)" if c in required else "") for c in rep["unmapped"]]
    add("unmapped:  " + (", ".join(unm) if unm else "none"))
    if rep["notes"]:
        add("notes:")
        for n in rep["notes"]:
            add(f"  - {n}")
    return "\n".join(out) + "\n"


def _inspect_markers(args: argparse.Namespace) -> int:
    """Marker files: labels, rate, units, gaps per marker, roles found, markers left unused."""
    from pathlib import Path

    from ..markers.joints import up_axis
    from ..markers.markerset import marker_set_toml, recording_marker_set
    from ..sources.markers import read_markers

    path = Path(args.input)
    rec = read_markers(path, args.units)
    ms = recording_marker_set(rec, args.marker_set)
    if args.emit_markerset:
        sys.stdout.write(marker_set_toml(rec.labels, ms))
        return 0
    gaps = rec.gaps()
    k = int(np.argmax(np.abs(up_axis(rec, ms))))
    up = "XYZ"[k]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-gap frames
        span = np.nanmax(rec.positions[..., k], axis=1) - np.nanmin(rec.positions[..., k], axis=1)
        height = float(np.nanmedian(span)) if np.isfinite(span).any() else None
    rep = {
        "file": str(path),
        "frames": rec.num_frames,
        "fps": rec.fps,
        "markers": len(rec.labels),
        "units": args.units if args.units is not None else "from the file",
        "marker_height_m": height,
        "up_axis": up,
        "roles": {role: rec.labels[i] for role, i in sorted(ms.roles.items())},
        "role_choices": dict(sorted(ms.choices.items())),
        "unused": list(ms.unused),
        "gaps": {lab: {"frames": n, "share": n / rec.num_frames} for lab, n in gaps.items()},
    }
    if args.json:
        sys.stdout.write(json.dumps(rep, indent=2, allow_nan=False) + "\n")
        return 0
    out = [
        f"file:      {path} (markers)",
        f"frames:    {rec.num_frames} at {rec.fps:.6g} fps; {len(rec.labels)} markers; up axis {up} (from the markers)",
        f"units:     {rep['units']}; the markers span {_fmt(height, '.3g')} m vertically (median over frames)",
        f"roles:     {len(ms.roles)} found: " + ", ".join(f"{r}={rec.labels[i]}" for r, i in sorted(ms.roles.items())),
        *(f"chosen:    {why}" for _, why in sorted(ms.choices.items())),
        f"unused:    {', '.join(ms.unused) if ms.unused else '(none)'}",
        "gaps:      " + (", ".join(f"{lab} {n} frames" for lab, n in sorted(gaps.items())) if gaps else "(none)"),
    ]
    sys.stdout.write("\n".join(out) + "\n")
    return 0


def run(args: argparse.Namespace) -> int:
    from ..sources import load_motion
    from ..sources.markers import MARKER_FILE_TYPES, is_marker_file
    from ..sources.profiles import map_skeleton

    if is_marker_file(args.input):
        return _inspect_markers(args)
    if args.emit_markerset or args.marker_set:
        raise OptionError(f"--emit-markerset and --marker-set are for marker files ({MARKER_FILE_TYPES})")

    opts: dict[str, Any] = {}
    if args.units is not None:
        opts["units"] = args.units
    if args.up is not None:
        opts["up"] = args.up.upper()
    motion = load_motion(args.input, **opts)
    jmap = map_skeleton(motion, profile=args.profile, mapping=args.map, required=())
    missing = jmap.missing(REQUIRED_JOINTS)
    if args.emit_map:
        sys.stdout.write(jmap.to_toml())
        if missing:
            warn(f"{motion.source}: required canonical joints still unmapped: {', '.join(missing)}; "
                 "fill them in the [joints] table")
        return 0
    rep = describe(motion, jmap)
    if args.json:
        sys.stdout.write(json.dumps(rep, indent=2, allow_nan=False) + "\n")
    else:
        sys.stdout.write(_text(rep))
    sys.stdout.flush()
    if missing:
        names = [n for j, n in enumerate(motion.skeleton.names) if not motion.skeleton.end_site[j]]
        raise MappingError(
            f"cannot map the required canonical joint(s) {', '.join(missing)} "
            f"(profile {jmap.profile}); the skeleton's joints are: {', '.join(names)}. "
            "Write a mapping file (start from --emit-map) and pass it with --map",
            path=motion.source,
        )
    return 0
