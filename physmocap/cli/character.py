"""``physmocap character``: describe a character (``info``), build a scaled humanoid (``scale``),
propose a mapping file for a robot MJCF (``init``)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import TextIO



def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "character",
        help="describe a character: bodies, joints and limits, sites, contacts, segments",
        description="Inspect MJCF characters and their mapping files.",
    )
    csub = p.add_subparsers(dest="character_command", metavar="ACTION")

    info = csub.add_parser(
        "info",
        help="print bodies, degrees of freedom with limits, sites, contact points, segment lengths, mass",
        description=(
            "Load a character (default: the bundled humanoid; a bundled name such as 'robot'; or an "
            "MJCF file with its mapping file) and print what the retargeter knows about it."
        ),
    )
    info.add_argument("path", nargs="?", metavar="PATH", help="MJCF file or bundled name (default: humanoid)")
    info.add_argument("--map", metavar="MAP.toml", help="mapping file (default: <stem>.map.toml beside the MJCF)")
    info.add_argument(
        "--range-policy",
        choices=["default", "strict"],
        help="joint ranges of the default humanoid's joints: performer margin (default) or clinical (strict)",
    )
    info.add_argument("--json", action="store_true", help="print the description as JSON")
    info.set_defaults(func=run_info)

    scale = csub.add_parser(
        "scale",
        help="write a copy of the default humanoid scaled to an actor's height or segment lengths",
        description=(
            "Build a copy of the default humanoid with an actor's proportions using MuJoCo's model "
            "editing API (MjSpec), from a stature and/or measured segment lengths. Writes OUT.xml and "
            "OUT.map.toml; use it with --character OUT.xml."
        ),
    )
    scale.add_argument("-o", "--output", required=True, metavar="OUT.xml", help="MJCF file to write")
    scale.add_argument("--height", type=float, metavar="M", help="actor's stature in metres")
    scale.add_argument(
        "--segment",
        action="append",
        default=[],
        metavar="PARENT:CHILD=M",
        help="a measured segment length, e.g. left_hip:left_knee=0.44 (repeatable; the other side is mirrored)",
    )
    scale.add_argument("--mass", type=float, metavar="KG", help="actor's body mass in kg")
    scale.set_defaults(func=run_scale)

    init = csub.add_parser(
        "init",
        help="propose a mapping file for a humanoid MJCF (a robot) from its body names and tree",
        description=(
            "Propose a mapping file for a humanoid MJCF: the free-joint body is the pelvis, the legs and "
            "arms are found by the kinematic tree, their sides and parts by name (left_/l_/L_/Left, hip, "
            "knee, calf, ankle, shoulder, elbow, wrist...) or by position. Prints the TOML on stdout (or "
            "writes it with -o) and what it guessed on stderr. Use it with --map, or name it "
            "<stem>.map.toml beside the MJCF."
        ),
    )
    init.add_argument("path", metavar="ROBOT.xml", help="MJCF file of a humanoid with a free joint")
    init.add_argument("-o", "--output", metavar="ROBOT.map.toml", help="write the mapping here (default: stdout)")
    init.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
    init.set_defaults(func=run_init)

    def _no_action(args: argparse.Namespace) -> int:
        p.print_help(sys.stderr)
        return 2

    p.set_defaults(func=_no_action)


def describe(ch) -> dict:
    """A JSON-ready description of a :class:`~physmocap.models.Character` (degrees, metres, kg);
    ``untracked_limbs`` only for a character without some optional limb."""
    from ..models.character import untracked_limbs

    model = ch.model
    data = ch.rest_data()
    bodies = []
    for b in range(1, model.nbody):
        bodies.append(
            {
                "name": model.body(b).name,
                "parent": model.body(int(model.body_parentid[b])).name or "world",
                "mass": float(model.body_mass[b]),
            }
        )
    joints = []
    for j in range(model.njnt):
        jtype = int(model.jnt_type[j])
        kind = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}[jtype]
        entry: dict = {"name": model.joint(j).name, "type": kind, "body": model.body(int(model.jnt_bodyid[j])).name}
        if kind in ("hinge", "slide"):
            k = 180.0 / math.pi if kind == "hinge" else 1.0
            lo, hi = ch.joint_limits[entry["name"]]
            entry["axis_world"] = [round(float(x), 6) + 0.0 for x in data.xaxis[j]]
            entry["range"] = [lo * k if math.isfinite(lo) else None, hi * k if math.isfinite(hi) else None]
            entry["velocity_limit"] = ch.velocity_limits[entry["name"]] * k
            entry["units"] = "deg, deg/s" if kind == "hinge" else "m, m/s"
        joints.append(entry)
    sites = [
        {"name": model.site(s).name, "body": model.body(int(model.site_bodyid[s])).name,
         "rest_position": [float(x) for x in data.site_xpos[s]]}
        for s in range(model.nsite)
    ]
    rest = ch.rest_positions()
    untracked = {"untracked_limbs": list(limbs)} if (limbs := untracked_limbs(ch.tracked)) else {}
    return {
        "name": ch.name,
        "mjcf": str(ch.mjcf_path),
        "mapping": None if ch.map_path is None else str(ch.map_path),
        "mapping_proposed": bool(getattr(ch, "mapping_proposed", False)),
        "root_joint": ch.root_joint,
        "rest_pose": getattr(ch, "rest_pose", ""),
        "height": ch.height,
        "hip_height": ch.hip_height,
        "total_mass": ch.total_mass,
        "dof": int(model.nv),
        "velocity_groups": [list(g) for g in getattr(ch, "velocity_groups", ())],
        "bodies": bodies,
        "joints": joints,
        "sites": sites,
        "tracked": {
            c: {"kind": tf.kind, "name": tf.name, "rest_position": [float(x) for x in rest[c]]}
            for c, tf in ch.tracked.items()
        },
        **untracked,
        "contacts": {side: list(names) for side, names in ch.contacts.items()},
        "segment_lengths": [
            {"parent": p, "child": c, "length": length} for (p, c), length in ch.segment_lengths.items()
        ],
    }


def _fmt_range(lo: float | None, hi: float | None) -> str:
    if lo is None or hi is None:
        return "unlimited"
    return f"[{lo:8.1f}, {hi:7.1f}]"


def print_info(desc: dict, out: TextIO) -> None:
    w = out.write
    w(f"character  {desc['name']}\n")
    w(f"mjcf       {desc['mjcf']}\n")
    implicit = (
        "(none found: proposed by `physmocap character init`, not saved)"
        if desc.get("mapping_proposed")
        else "(none: sites named like canonical joints)"
    )
    w(f"mapping    {desc['mapping'] or implicit}\n")
    w(f"root       {desc['root_joint']} (free joint), {desc['dof']} degrees of freedom\n")
    if desc.get("rest_pose"):
        w(f"rest pose  {desc['rest_pose']}\n")
    w(f"height     {desc['height']:.3f} m    hip height {desc['hip_height']:.3f} m    "
      f"total mass {desc['total_mass']:.2f} kg\n")

    w(f"\nbodies ({len(desc['bodies'])})\n")
    depth = {"world": -1}
    for b in desc["bodies"]:
        depth[b["name"]] = depth.get(b["parent"], -1) + 1
        w(f"  {'  ' * depth[b['name']]}{b['name']:<{max(1, 28 - 2 * depth[b['name']])}} {b['mass']:7.3f} kg\n")

    hinges = [j for j in desc["joints"] if j["type"] in ("hinge", "slide")]
    w(f"\ndegrees of freedom ({len(hinges)} hinge/slide; range in deg, speed in deg/s)\n")
    w(f"  {'joint':<28} {'body':<18} {'range':>18} {'speed':>8}  axis (world, rest)\n")
    for j in desc["joints"]:
        if j["type"] not in ("hinge", "slide"):
            w(f"  {j['name']:<28} {j['body']:<18} {j['type']}\n")
            continue
        ax = " ".join(f"{x:+.3f}" for x in j["axis_world"])
        unit = "" if j["type"] == "hinge" else " (m)"
        w(f"  {j['name']:<28} {j['body']:<18} {_fmt_range(*j['range']):>18} "
          f"{j['velocity_limit']:8.0f}  {ax}{unit}\n")

    if desc.get("velocity_groups"):
        w("  speed of these hinges (one body, one anchor, human limits): the body's angular speed along each axis,\n"
          "  not the hinge's rate:\n")
        for g in desc["velocity_groups"]:
            w(f"    {', '.join(g)}\n")

    w(f"\ntracked canonical joints ({len(desc['tracked'])}; rest position in m)\n")
    for c, t in desc["tracked"].items():
        x, y, z = t["rest_position"]
        w(f"  {c:<16} {t['kind']:<4} {t['name']:<22} {x:7.3f} {y:7.3f} {z:7.3f}\n")
    if desc.get("untracked_limbs"):
        limbs = ", ".join(x.replace("_", " ") for x in desc["untracked_limbs"])
        w(f"  not tracked: {limbs} (the character has none: the actor's are not retargeted)\n")

    w("\ncontact points (sites)\n")
    for side, names in desc["contacts"].items():
        w(f"  {side:<6} {', '.join(names)}\n")
    if not desc["contacts"]:
        w("  (none)\n")

    w(f"\nsites ({len(desc['sites'])})\n")
    for s in desc["sites"]:
        x, y, z = s["rest_position"]
        w(f"  {s['name']:<22} on {s['body']:<18} {x:7.3f} {y:7.3f} {z:7.3f}\n")

    w("\nsegment lengths (m, rest pose)\n")
    for s in desc["segment_lengths"]:
        w(f"  {s['parent'] + ' -> ' + s['child']:<34} {s['length']:.4f}\n")


def run_info(args: argparse.Namespace) -> int:
    from ..models import load_character

    ch = load_character(args.path, args.map, range_policy=args.range_policy)
    desc = describe(ch)
    if args.json:
        json.dump(desc, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print_info(desc, sys.stdout)
    return 0


def _parse_segment(text: str) -> tuple[tuple[str, str], float]:
    from ..errors import OptionError

    try:
        names, value = text.split("=", 1)
        parent, child = names.split(":", 1)
        length = float(value)
    except ValueError:
        raise OptionError(f"--segment {text!r}: expected PARENT:CHILD=METRES, e.g. left_hip:left_knee=0.44") from None
    return (parent.strip(), child.strip()), length


def run_scale(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..errors import OptionError
    from ..models.scaling import write_scaled_humanoid

    if Path(args.output).suffix.lower() != ".xml":
        raise OptionError("the scaled character is an MJCF file: give it a .xml name", path=args.output)
    if args.height is not None and not (0.5 <= args.height <= 2.5):
        raise OptionError(f"--height must be a human stature in metres (0.5 to 2.5), got {args.height:g}")

    if args.height is None and not args.segment:
        raise OptionError("give --height and/or --segment PARENT:CHILD=M")
    lengths = dict(_parse_segment(s) for s in args.segment)
    ch = write_scaled_humanoid(args.output, segment_lengths=lengths, height=args.height, mass=args.mass)
    print(
        f"wrote {args.output} and {ch.map_path}: height {ch.height:.3f} m, "
        f"hip height {ch.hip_height:.3f} m, mass {ch.total_mass:.1f} kg",
        file=sys.stderr,
    )
    return 0


def run_init(args: argparse.Namespace) -> int:
    import os
    import tempfile
    from pathlib import Path

    from ..errors import MappingError, OutputError
    from ..fileio import atomic_open, check_not_input, check_writable
    from ..models import load_character
    from ..models.propose import propose_mapping

    out = Path(args.output) if args.output else None
    if out is not None:
        check_not_input([out], [args.path])
        if out.exists() and not out.is_dir() and not args.force:
            raise OutputError("exists; use --force to overwrite it", path=out)
        check_writable(args.output)
    proposal = propose_mapping(args.path)
    text = proposal.to_toml()
    for line in proposal.report():
        print(line, file=sys.stderr)
    # the proposal must load as a character: check it before handing it over
    fd, tmp = tempfile.mkstemp(prefix="physmocap-init-", suffix=".map.toml")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        try:
            ch = load_character(args.path, tmp)
        except MappingError as exc:
            raise MappingError(f"the proposed mapping does not load ({exc.message}); "
                               "write one by hand (README, Characters)", path=args.path) from None
    finally:
        os.unlink(tmp)
    print(f"  checked: loads as a character, height {ch.height:.2f} m, hip height {ch.hip_height:.2f} m, "
          f"foot contacts {', '.join(n for side in ch.contacts.values() for n in side) or 'none'}",
          file=sys.stderr)
    if out is None:
        sys.stdout.write(text)
    else:
        with atomic_open(out) as fh:
            fh.write(text)
        print(f"wrote {out}", file=sys.stderr)
    return 0
