"""``physmocap solve``: a marker recording (C3D, TRC, marker MCAP) to the actor's own skeleton as BVH."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import OptionError
from ..fileio import OutputSet, announce, atomic_open, check_distinct, check_not_input, check_writable, suffix_error

if TYPE_CHECKING:  # numpy and mujoco stay unimported until a command runs
    from ..markers.solve import MarkerSolveOptions


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "solve",
        help="solve optical markers (.c3d, .trc, marker .mcap) into the actor's skeleton (BVH out)",
        description=(
            "Calibrate the actor from the markers (functional joint centres, fixed segment lengths), "
            "then solve every frame by marker-driven IK under the joint ranges and the floor, and write "
            "the actor's skeleton (canonical joint names) as BVH."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="marker file (.c3d, .trc, or .mcap with labelled markers)")
    p.add_argument("-o", "--output", required=True,
                   help="output .bvh (the actor); with --character, the character's motion: .bvh, .npz, .csv or .mcap")
    p.add_argument("--character", metavar="PATH",
                   help="also retarget the solved actor onto this character (MJCF file or bundled name: humanoid, "
                   "robot) with the retargeter; -o is then the character's motion")
    p.add_argument("--map", metavar="MAP.toml", help="the character's mapping file (TOML), with --character")
    p.add_argument("--actor", metavar="ACTOR.bvh", help="with --character, also write the solved actor as BVH")
    p.add_argument("--in-units", metavar="UNIT",
                   help="override the marker file's length unit: mm, cm, m, in, ft or metres per unit (default: the file's)")
    p.add_argument("--report", metavar="REPORT.json", help="write the residual and gap report as JSON")
    p.add_argument("--marker-set", metavar="SET.toml", help="marker roles overriding the built-in aliases")
    p.add_argument("--start", type=int, help="first frame (inclusive)")
    p.add_argument("--end", type=int, help="last frame (exclusive)")
    add_marker_solve_options(p)
    p.add_argument("--up", choices=["Y", "Z", "y", "z"], default="Y", help="BVH output up axis (default Y)")
    p.add_argument("--units", default="m", help="BVH output length unit (default m)")
    p.add_argument("--quiet", action="store_true", help="no residual table or 'wrote' lines")
    p.set_defaults(func=run)


def add_marker_solve_options(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """The flags of :class:`~physmocap.markers.solve.MarkerSolveOptions` a user sets, read back
    by :func:`marker_solve_options`: ``--{prefix}max-iterations N`` and ``--{prefix}no-floor``.
    ``solve`` takes them bare; ``retarget`` (and ``preview``, ``view``, ``batch``), whose
    ``--max-iterations`` and ``--no-floor`` are the character's, with ``prefix="marker-"``."""
    what = "marker files: the actor's " if prefix else ""
    p.add_argument(f"--{prefix}max-iterations", dest="marker_max_iterations", type=int, metavar="N",
                   help=f"{what}marker-driven IK iterations per frame (default 2)")
    p.add_argument(f"--{prefix}no-floor", dest="marker_no_floor", action="store_true",
                   help=f"{what}marker solve without the floor constraint (feet may go below it)"
                   + ("" if prefix else "; with --character, the character's too"))


def marker_solve_options(args: argparse.Namespace) -> "MarkerSolveOptions | None":
    """The :class:`~physmocap.markers.solve.MarkerSolveOptions` of the flags of
    :func:`add_marker_solve_options`, validated; None when none is set (the defaults).

    Raises:
        OptionError: A value the options refuse (an iteration count below 1...).
    """
    from ..markers.solve import MarkerSolveOptions

    changes: dict = {}
    if getattr(args, "marker_max_iterations", None) is not None:
        changes["max_iterations"] = args.marker_max_iterations
    if getattr(args, "marker_no_floor", False):
        changes["floor"] = False
    return MarkerSolveOptions(**changes) if changes else None


def run(args: argparse.Namespace) -> int:
    from ..markers.solve import MarkerSolveOptions, print_report, solve_markers, write_actor_bvh
    from ..options import check_frame_range
    from ..sources.markers import read_markers
    from .retarget import WRITERS

    out = Path(args.output)
    actor_out = Path(args.actor) if args.actor else None
    if args.character is None:
        if out.suffix.lower() != ".bvh":
            raise OptionError("physmocap solve writes a .bvh file (or, with --character, .bvh/.npz/.csv/.mcap)", path=out)
        if args.actor or args.map:
            raise OptionError("--actor and --map go with --character")
        actor_out, out = out, None
    elif out.suffix.lower() not in WRITERS:
        raise suffix_error(out, WRITERS)
    if actor_out is not None and actor_out.suffix.lower() != ".bvh":
        raise OptionError("the actor is written as .bvh", path=actor_out)
    outputs = [x for x in (out, actor_out, Path(args.report) if args.report else None) if x is not None]
    for x in (args.output, args.actor, args.report):  # as typed: a trailing separator is refused
        if x:
            check_writable(x)
    check_not_input(outputs, [args.input, args.marker_set, args.map])
    check_distinct(outputs)
    check_frame_range(args.start, args.end)
    opts = marker_solve_options(args) or MarkerSolveOptions()
    rec = read_markers(args.input, args.in_units).frames(args.start, args.end)
    character = None
    if args.character is not None:
        from ..models import load_character

        character = load_character(args.character, args.map)  # a bad character fails before the solve
    sol = solve_markers(rec, args.marker_set, opts)
    rep = sol.report()
    traj = None
    if character is not None:
        from ..ik.retarget import retarget
        from ..markers.solve import actor_motion

        traj = retarget(actor_motion(sol), character, progress=False if args.quiet else None,
                        floor=opts.floor)
    with OutputSet():
        if actor_out is not None:
            write_actor_bvh(sol, actor_out, up=args.up.upper(), units=args.units)
            if not args.quiet:
                announce(f"wrote {actor_out}")
        if traj is not None:
            from .retarget import write_outputs

            # --up and --units are the actor BVH's: the character's output takes them if a BVH
            bvh = Path(out).suffix.lower() == ".bvh"
            write_outputs(traj, [out], args if bvh else argparse.Namespace(**{**vars(args), "up": None, "units": None}),
                          quiet=args.quiet)
        if args.report:
            with atomic_open(args.report) as fh:
                json.dump(rep, fh, indent=1)
            if not args.quiet:
                announce(f"wrote {args.report}")
    if not args.quiet:
        print_report(rep, frames_per_second=sol.frames_per_second()[0])
    return 0
