"""``physmocap clean``: find and repair capture glitches in a BVH (or any source) file."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import OptionError
from ..fileio import OutputSet, announce, atomic_open, check_distinct, check_not_input, check_writable


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "clean",
        help="find and repair capture glitches (spikes, flips, frozen joints, out-of-range joints, swaps)",
        description=(
            "Detect glitches in the source skeleton (spikes, flips, discontinuities, frozen joints, "
            "joints beyond their range of motion named by anatomical movement; bone stretch, gaps and "
            "left/right swaps on joint-position sources), repair the repairable ones by interpolating "
            "over them, and write the same file layout (a drop-in replacement)."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file (.bvh, ...) or 'example'")
    p.add_argument("-o", "--output", help="cleaned BVH (same hierarchy, channels, frames and frame time)")
    p.add_argument("--report", metavar="GLITCHES.json", help="write the glitch list as JSON")
    p.add_argument(
        "--plots",
        metavar="DIR",
        help="write PNGs: anatomical angles with their ranges and the spans beyond them, and each glitched "
        "joint's speed with its glitched spans (needs: pip install 'physmocap[plot]')",
    )
    p.add_argument(
        "--source-map",
        metavar="MAP.toml",
        help="source skeleton mapping file (TOML, as retarget takes; physmocap inspect FILE --emit-map writes "
        "one): names the joints of a skeleton or tracker no profile knows, for the left/right pairs, the "
        "hierarchy of a joint-position file's bones and the ranges of motion",
    )
    p.add_argument("--marker-set", metavar="SET.toml", help="marker files (.c3d, .trc, marker .mcap): marker roles overriding the aliases")
    p.add_argument(
        "--resolve",
        choices=("never", "limits", "always"),
        default="limits",
        help="re-solve rotational repairs through the hard-limited IK on an actor-fitted humanoid: where the "
        "interpolated pose leaves a range of motion (limits, the default), never, or wherever the joint can be "
        "(always; interpolation is better on average)",
    )
    add_clean_options(p)
    p.set_defaults(func=run)


#: Readers that build a joint-position skeleton from the source mapping as they read.
POSITIONAL_SUFFIXES = {".csv", ".npz", ".jsonl", ".c3d", ".trc"}


def _flag(name: str) -> str:
    """The command-line flag of the :class:`~physmocap.clean.CleanOptions` field ``name``."""
    return "--" + name.replace("_", "-")


def add_clean_options(p: argparse.ArgumentParser) -> None:
    """One flag per :class:`~physmocap.clean.CleanOptions` field (``jump_deg`` ->
    ``--jump-deg``), generated from the fields: its type, unit, default and the field's own
    documentation as the help.  Unset flags keep the defaults (:func:`options_from_args`)."""
    from dataclasses import MISSING, fields

    from ..clean.options import CleanOptions, option_docs, option_unit

    docs = option_docs()
    group = p.add_argument_group(
        "detection and repair thresholds",
        "each a physical quantity (seconds, degrees, metres, per second), never frames",
    )
    for f in fields(CleanOptions):
        unit = option_unit(f.name)
        kind = int if unit == "count" else float
        default = f.default if f.default is not MISSING else None
        physical = unit not in ("ratio", "count")
        text = f"{docs[f.name]} (default {default:g}{' ' + unit if physical else ''})"
        metavar = unit.upper() if physical else {"ratio": "X", "count": "N"}[unit]
        group.add_argument(_flag(f.name), type=kind, default=None, metavar=metavar, help=text.replace("%", "%%"))


def options_from_args(args: argparse.Namespace):
    """The :class:`~physmocap.clean.CleanOptions` the flags of :func:`add_clean_options` ask
    for (defaults for the unset ones), validated before any file is read.

    Raises:
        OptionError: A value the options refuse, naming its flag (``--still-speed must be
            > 0, got -1.0``).
    """
    from dataclasses import fields

    from ..clean import CleanOptions

    given = {f.name: getattr(args, f.name) for f in fields(CleanOptions) if getattr(args, f.name, None) is not None}
    for name, value in given.items():  # one at a time: the error names the flag that is wrong
        try:
            CleanOptions(**{name: value})
        except OptionError as exc:
            prefix = f"clean option {name} "
            text = exc.message[len(prefix):] if exc.message.startswith(prefix) else exc.message
            raise OptionError(f"{_flag(name)} {text}") from None
    return CleanOptions(**given)


def run(args: argparse.Namespace) -> int:
    from ..clean import clean
    from ..sources import load_motion
    from ..sources.markers import MARKER_FILE_TYPES, is_marker_file

    options = options_from_args(args)
    if args.output:
        if Path(args.output).suffix.lower() != ".bvh":
            raise OptionError("clean writes .bvh files", path=args.output)
        check_writable(args.output)
    if args.report:
        check_writable(args.report, "report")
    if args.plots:
        from ..fileio import check_output_dir
        from ..plots import require_matplotlib

        require_matplotlib()
        check_output_dir(args.plots, "plot directory")
    check_not_input([args.output, args.report], [args.input, args.source_map, args.marker_set])
    check_distinct([args.output, args.report])
    suffix = Path(args.input).suffix.lower()
    if args.marker_set and not is_marker_file(args.input):
        raise OptionError(f"--marker-set is for marker files ({MARKER_FILE_TYPES})", path=args.input)
    read_opts = {}
    if args.source_map and suffix in POSITIONAL_SUFFIXES:
        read_opts["mapping"] = args.source_map  # the bones follow the mapped joints
    if args.marker_set:
        read_opts["marker_set"] = args.marker_set
    motion = load_motion(args.input, min_frames=1, **read_opts)
    if args.output and not motion.is_rotational:
        raise OptionError("a joint-position source has no rotations to write as BVH; use --report", path=args.input)
    fixed, report = clean(motion, options, mapping=args.source_map, resolve=args.resolve)
    sys.stdout.write(report.table())
    with OutputSet():  # the BVH, the plots and the JSON renamed into place together, or none
        _write(motion, fixed, report, args)
    return 0


def _write(motion, fixed, report, args: argparse.Namespace) -> None:
    if args.output:
        from ..export.bvh import write_bvh

        write_bvh(fixed, args.output)
        announce(f"wrote {args.output}")
    if args.plots:
        from ..clean.plots import write_glitch_plots

        for path in write_glitch_plots(motion, report.glitches, args.plots):
            announce(f"wrote {path}")
    if args.report:
        with atomic_open(args.report) as fh:
            json.dump(report.as_dict(), fh, indent=2, sort_keys=True, allow_nan=False)
            fh.write("\n")
        announce(f"wrote {args.report}")
