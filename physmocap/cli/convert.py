"""``physmocap convert IN OUT``: rewrite a motion file, optionally changing it.

Reads ``IN`` with :func:`physmocap.sources.load_motion` and writes ``OUT`` with
:func:`physmocap.export.write_motion`, both chosen by file suffix, so every
supported format converts to every writable one.  In order, it: cuts the frame
range ``[--start, --end)``, resamples to ``--fps`` (slerp for rotations, linear
for translations), then writes with the requested rotation order, units, up
axis and precision (by default those of the input file).
"""

from __future__ import annotations

import argparse
import sys

from ..errors import OptionError
from ..resources import display_path


def register(subparsers) -> None:  # noqa: ANN001
    p = subparsers.add_parser(
        "convert",
        help="rewrite a motion file as BVH or MCAP, optionally changing units, axes, rate or range",
        description=(
            "Read IN (any supported format, chosen by suffix; 'example' is the bundled walk) and write "
            "OUT (by suffix). In order: cut the frame range [--start, --end), resample to --fps (slerp "
            "for rotations, linear for translations), then write with the requested rotation order, "
            "units, up axis and precision (by default those of the input)."
        ),
    )
    p.add_argument("input", metavar="IN", help="input motion file, or 'example' for the bundled walk")
    p.add_argument("output", metavar="OUT", help="output file, by suffix: .bvh (rotational sources) or .mcap "
                   "(Foxglove FrameTransforms; any source; marker files (.c3d, .trc, marker .mcap) as labelled points)")
    p.add_argument("--rotation-order", metavar="ORDER",
                   help="Euler order for every joint, e.g. ZXY, ZYX, XYZ (default: keep the input's)")
    p.add_argument("--units", metavar="UNIT",
                   help="BVH output length unit: m, dm, cm, mm, inch, ft, cmu, or metres per unit (default: the input's)")
    p.add_argument("--up", metavar="AXIS", choices=["Y", "Z", "y", "z"],
                   help="output up axis, Y or Z (default: the input's)")
    p.add_argument("--precision", metavar="N", type=int, default=None,
                   help="decimals written for every number (default 6)")
    p.add_argument("--start", metavar="FRAME", type=int, default=None,
                   help="first frame to keep (0-based, default 0)")
    p.add_argument("--end", metavar="FRAME", type=int, default=None,
                   help="frame to stop before (exclusive, default: the end of the clip)")
    p.add_argument("--fps", metavar="RATE", type=float, default=None,
                   help="resample to this frame rate (quaternion slerp)")
    p.add_argument("--in-units", metavar="UNIT",
                   help="the input's length unit when it cannot be detected reliably: m, dm, cm, mm, inch, ft, cmu (CMU BVH), or metres per unit as a number (default: detect)")
    p.add_argument("--in-up", metavar="AXIS", choices=["Y", "Z", "y", "z"],
                   help="the input's up axis (default: the format's convention, Y for BVH)")
    p.set_defaults(func=run)


def _check_output(output: str, options: dict) -> None:
    """Fail on a bad output path or option before reading the input."""
    from pathlib import Path

    from ..errors import OutputError
    from ..export import MOTION_WRITERS
    from ..fileio import check_writable

    suffix = Path(output).suffix.lower()
    if suffix not in MOTION_WRITERS:
        known = ", ".join(sorted(MOTION_WRITERS))
        raise OutputError(f"unknown output type {suffix or '(none)'!r}; physmocap writes {known}", path=output)
    check_writable(output)
    if suffix == ".bvh":
        from ..export.bvh import check_bvh_options

        check_bvh_options(**options)


def run(args: argparse.Namespace) -> int:
    from ..export import write_motion
    from ..fileio import check_not_input
    from ..options import check_frame_range
    from ..sources import load_motion
    from ..sources.markers import is_marker_file

    check_not_input([args.output], [args.input])
    check_frame_range(args.start, args.end)

    in_opts = {}
    if args.in_units is not None:
        in_opts["units"] = args.in_units
    if args.in_up is not None:
        in_opts["up"] = args.in_up.upper()
    out_opts = {}
    if args.rotation_order is not None:
        out_opts["rotation_order"] = args.rotation_order
    if args.units is not None:
        out_opts["units"] = args.units
    if args.up is not None:
        out_opts["up"] = args.up.upper()
    if args.precision is not None:
        out_opts["precision"] = args.precision
    if args.fps is not None and not (args.fps > 0 and args.fps < float("inf")):
        raise OptionError(f"--fps must be a positive frame rate, got {args.fps:g}")

    _check_output(args.output, out_opts)
    if is_marker_file(args.input) and args.output.lower().endswith(".mcap"):
        return _convert_markers(args, out_opts)
    motion = load_motion(args.input, **in_opts)
    F = motion.num_frames
    ends = int(motion.skeleton.end_site.sum())
    print(
        f"physmocap: read {display_path(motion.source)}: {F} frames at {motion.fps:.6g} fps, "
        f"{motion.skeleton.num_joints - ends} joints and {ends} end sites, units {motion.units}, {motion.file_up}-up",
        file=sys.stderr,
    )
    if args.start is not None or args.end is not None:
        start = 0 if args.start is None else args.start
        end = F if args.end is None else args.end
        if not (0 <= start < end <= F):
            raise OptionError(
                f"--start {start} --end {end}: the frame range must satisfy 0 <= start < end <= {F} "
                f"(the clip has {F} frames, numbered 0 to {F - 1}; end is exclusive)"
            )
        motion = motion.slice_frames(start, end)
    if args.fps is not None:
        if motion.num_frames < 2:
            raise OptionError("--fps needs at least two frames to resample")
        motion = motion.resample(args.fps)
    out = write_motion(motion, args.output, **out_opts)
    print(f"physmocap: wrote {out}: {motion.num_frames} frames at {motion.fps:.6g} fps", file=sys.stderr)
    return 0


def _convert_markers(args: argparse.Namespace, out_opts: dict) -> int:
    """A marker file (.c3d, .trc, marker .mcap) to an MCAP marker recording (labelled points,
    metres, the file's axes: :func:`physmocap.export.mcap.write_markers_mcap`), cut to
    [--start, --end)."""
    from ..export.mcap import write_markers_mcap
    from ..sources.markers import read_markers

    if out_opts or args.fps is not None or args.in_up is not None:
        raise OptionError("a marker recording is written to MCAP as it is (metres, the file's axes): "
                          "--rotation-order, --units, --up, --precision, --fps and --in-up do not apply")
    whole = read_markers(args.input, args.in_units)
    F = whole.num_frames
    rec = whole.frames(args.start, args.end)
    print(f"physmocap: read {rec.source}: {F} frames at {rec.fps:.6g} fps, {len(rec.labels)} markers", file=sys.stderr)
    out = write_markers_mcap(rec, args.output)
    print(f"physmocap: wrote {out}: {rec.num_frames} frames of labelled markers at {rec.fps:.6g} fps", file=sys.stderr)
    return 0
