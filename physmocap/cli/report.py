"""``physmocap report``: quality figures of a retargeted trajectory, source versus result."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import OptionError, warn


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="measure a retargeted trajectory (skating, penetration, hovering, limits, tracking)",
        description=(
            "Print a table of quality figures (definitions: docs/metrics.md) for a "
            "trajectory written by 'physmocap retarget --qpos OUT.npz', next to the same figures "
            "on its source motion; optionally write them as JSON and draw PNG plots."
        ),
    )
    p.add_argument("trajectory", metavar="TRAJECTORY.npz", help="joint trajectory from physmocap retarget --qpos")
    p.add_argument("--source", metavar="CLIP", help="source motion (default: the path stored in the trajectory)")
    p.add_argument("--no-source", action="store_true", help="report on the trajectory alone")
    p.add_argument("--json", metavar="OUT.json", help="also write the report as JSON")
    p.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR (needs: pip install 'physmocap[plot]')")
    p.add_argument("--contacts", metavar="LABELS.csv", help="contact labels (point,start,end) instead of detection")
    p.add_argument("--character", metavar="PATH", help="MJCF or bundled name (default: the one stored in the file)")
    p.add_argument("--map", metavar="MAP.toml", help="character mapping file")
    p.add_argument("--profile", help="force the source skeleton's naming profile")
    p.add_argument("--source-map", metavar="MAP.toml", help="source skeleton mapping file (TOML)")
    p.add_argument("--in-units", metavar="UNIT", help="override the source's length unit: m, dm, cm, mm, inch, ft, cmu (CMU BVH), or metres per unit as a number (default: detect)")
    from .retarget import add_clean_option, add_marker_read_options

    add_marker_read_options(p)  # a marker source is read as the retarget read it
    add_clean_option(p)  # and cleaned as it cleaned it
    p.add_argument(
        "--start", type=int, default=None,
        help="source frame the trajectory starts at (retarget --start; default: stored in the file, else 0)"
    )
    p.set_defaults(func=run)


def _source_path(args: argparse.Namespace, stored: str) -> Path | None:
    if args.no_source:
        return None
    if args.source:
        return Path(args.source)
    from ..resources import EXAMPLE_NAME, resolve_input

    if stored == EXAMPLE_NAME:
        return resolve_input(stored)
    p = Path(stored)
    if stored and stored not in ("<memory>", "<unknown>") and p.exists():
        return p
    warn(f"the trajectory's source {stored!r} is not available; reporting on the result alone (pass --source)")
    return None


def run(args: argparse.Namespace) -> int:
    from ..fileio import check_not_input, check_writable
    from ..ik.contacts import detect_contacts, load_contact_csv
    from ..report import load_trajectory, tracking_targets

    if args.json:
        check_writable(args.json, "report")
        check_not_input([args.json], [args.trajectory, args.source, args.contacts, args.map, args.source_map])
    if args.plots:
        from ..fileio import check_output_dir
        from ..plots import require_matplotlib

        require_matplotlib()
        check_output_dir(args.plots, "plot directory")
    if args.start is not None and args.start < 0:
        raise OptionError(f"--start must be >= 0, got {args.start}")
    from .retarget import check_option_files

    check_option_files(args)  # before the trajectory and its source are read
    traj = load_trajectory(args.trajectory, args.character, args.map)
    if args.start is None:
        args.start = int(traj.source_start)
    F = traj.num_frames
    motion = None
    joint_indices = None
    src = _source_path(args, traj.source)
    from .retarget import cleaned_source, marker_read_options

    marker_opts = marker_read_options(args, src)  # refused without a marker source
    if src is not None:
        from ..ik.retarget import map_motion
        from ..sources import load_motion

        opts = {"units": args.in_units} if args.in_units else {}
        opts.update(marker_opts)
        motion = cleaned_source(load_motion(src, min_frames=1, **opts), args)
        # as retarget does: cut at the source's rate (--start is a source frame), then resample
        if args.start >= motion.num_frames:
            raise OptionError(f"--start {args.start} is past the source's {motion.num_frames} frames", path=src)
        if args.start:
            motion = motion.slice_frames(args.start, motion.num_frames)
        if abs(motion.fps - traj.fps) > 1e-6 * traj.fps:
            motion = motion.resample(traj.fps)
        if F > motion.num_frames:
            raise OptionError(
                f"the trajectory has {F} frames at {traj.fps:g} Hz but the source has only "
                f"{motion.num_frames} (from --start {args.start}); is this the right source?",
                path=src,
            )
        if F < motion.num_frames:
            motion = motion.slice_frames(0, F)
        joint_indices = map_motion(motion, profile=args.profile, mapping=args.source_map)
    if args.contacts:
        contacts = load_contact_csv(args.contacts, F, traj.fps)
    elif motion is not None:
        contacts = detect_contacts(motion, joint_indices)
    else:
        contacts = None
    if motion is not None and traj.targets is None:
        # files without stored targets: rebuild them (planting adjustments not reproduced)
        traj.targets = tracking_targets(motion, joint_indices, traj.character, contacts)
    from ..fileio import OutputSet

    with OutputSet():  # the JSON and the plots renamed into place together, or none
        _emit(traj, motion, contacts, joint_indices, args)
    return 0


def _emit(traj, motion, contacts, joint_indices, args: argparse.Namespace) -> None:
    from ..report import emit_report

    emit_report(
        traj,
        motion,
        contacts,
        json_path=args.json,
        plots_dir=args.plots,
        joint_indices=joint_indices,
        stream=sys.stdout,
    )
