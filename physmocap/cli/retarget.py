"""``physmocap retarget``: retarget a capture file onto a character and export it."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..errors import OptionError
from ..fileio import OutputSet, announce, check_distinct, check_not_input, check_writable, suffix_error


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "retarget",
        help="retarget a motion onto a character (BVH / NPZ / CSV / MCAP out)",
        description=(
            "Retarget solved motion onto an MJCF character with differential IK under joint "
            "limits, velocity limits and a floor. INPUT may be 'example' (the bundled CMU walk)."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file (.bvh, ...) or 'example'")
    p.add_argument("-o", "--output", required=True, help="output file: .bvh, .npz, .csv or .mcap")
    p.add_argument("--format", choices=["auto", "robot-csv", "robot-npz"], default="auto",
                   help="layout of -o: by suffix (auto), or the robot-learning CSV/NPZ (root pose + joint "
                   "positions, named; see README)")
    p.add_argument("--qpos", metavar="OUT.npz", help="also write the joint trajectory as NPZ")
    p.add_argument("--csv", metavar="OUT.csv", help="also write the joint trajectory as CSV")
    add_retarget_options(p)
    add_bvh_output_options(p)
    p.add_argument("--report", metavar="REPORT.json", help="print the quality report and write it as JSON")
    p.add_argument("--plots", metavar="DIR", help="write report plots (PNG) here (needs: pip install 'physmocap[plot]')")
    p.add_argument("--preview", metavar="OUT.mp4", help="also render a preview (.mp4, .gif or .png sheet; see physmocap preview)")
    p.set_defaults(func=run)


def add_retarget_options(p: argparse.ArgumentParser) -> None:
    """The options that say how to retarget (shared by ``retarget``, ``preview``, ``view`` and
    ``batch``), with the marker reader's (:func:`add_marker_read_options`)."""
    p.add_argument("--character", metavar="PATH", help="MJCF file or bundled name (humanoid, robot)")
    p.add_argument("--map", metavar="MAP.toml", help="character mapping file (TOML)")
    p.add_argument("--profile", help="force the source skeleton's naming profile")
    p.add_argument("--source-map", metavar="MAP.toml", help="source skeleton mapping file (TOML)")
    p.add_argument("--in-units", metavar="UNIT", help="override the input's length unit: m, dm, cm, mm, inch, ft, cmu (CMU BVH), or metres per unit as a number (default: detect)")
    p.add_argument("--in-up", metavar="AXIS", choices=["Y", "Z", "y", "z"],
                   help="a BVH input's up axis, Y or Z (default: Y, or Z where the rest pose and the motion are "
                        "both much taller along Z)")
    add_marker_read_options(p)
    add_clean_option(p)
    p.add_argument("--start", type=int, help="first source frame (inclusive)")
    p.add_argument("--end", type=int, help="last source frame (exclusive)")
    p.add_argument("--fps", type=float, help="resample the source to this frame rate first")
    p.add_argument("--max-iterations", type=int, help="IK iterations per frame")
    p.add_argument("--no-floor", action="store_true", help="do not constrain the character above the floor")
    p.add_argument("--no-velocity-limits", action="store_true", help="do not bound joint speeds")
    p.add_argument(
        "--no-self-collision",
        action="store_true",
        help="let the limbs pass through each other and the trunk (faster, mostly on mesh robots)",
    )
    p.add_argument(
        "--no-arm-branches",
        action="store_true",
        help="one pass only: do not retarget again an arm stuck on a branch of its joint ranges that cannot reach the actor",
    )
    p.add_argument(
        "--no-smooth-transitions",
        action="store_true",
        help="one pass fewer: do not retarget again with the joints pulled towards their own low-pass around contact changes",
    )
    p.add_argument(
        "--no-ease-caps",
        action="store_true",
        help="one pass fewer: do not retarget again with the joints that sit at their velocity caps spread out in time",
    )
    p.add_argument("--contacts", metavar="CONTACTS.csv", help="foot contact labels (frame ranges) instead of detection")
    p.add_argument("--no-plant", action="store_true", help="do not plant the feet (pure tracking)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar, report table or 'wrote' lines (warnings and errors still print)")


def add_marker_read_options(p: argparse.ArgumentParser) -> None:
    """How a marker input becomes the actor's motion (:data:`MARKER_OPTIONS_UNSET`; shared by the
    commands that retarget and by ``report``, which must read its source as the retarget did)."""
    from .solve import add_marker_solve_options

    p.add_argument("--marker-set", metavar="SET.toml", help="marker files (.c3d, .trc, marker .mcap): marker roles overriding the aliases")
    p.add_argument("--joint-centres", action="store_true",
                   help="marker files (.c3d, .trc, marker .mcap): retarget the markers' joint centres instead of the "
                   "actor solved from them (the default; see physmocap solve): faster, but no rigid actor skeleton "
                   "and no joint ranges before the character's")
    add_marker_solve_options(p, prefix="marker-")


def add_clean_option(p: argparse.ArgumentParser) -> None:
    """``--clean``: repair the source's capture glitches before retargeting (shared by the
    commands that retarget and by ``report``, which must compare with the source the retarget
    followed)."""
    p.add_argument(
        "--clean",
        action="store_true",
        help="repair the source's capture glitches first (flips, spikes, frozen joints...: physmocap clean with "
        "its defaults, on the whole file); the repairs are listed on stderr",
    )


def cleaned_source(motion, args: argparse.Namespace):
    """``motion`` with its capture glitches repaired when ``args.clean`` is set
    (:func:`physmocap.clean.clean` with default options, on the whole file, before any
    ``--start``/``--end`` cut or resampling), each repair named in one warning; ``motion``
    itself otherwise."""
    if not getattr(args, "clean", False):
        return motion
    from ..clean import clean
    from ..errors import warn

    fixed, report = clean(motion, mapping=getattr(args, "source_map", None))
    repaired = [g for g in report.glitches if g.corrected]
    if repaired:
        listed = "; ".join(f"{g.kind} {g.joint} {g.start}" + (f"-{g.end}" if g.end != g.start else "") for g in repaired[:8])
        more = f"; and {len(repaired) - 8} more" if len(repaired) > 8 else ""
        warn(f"{motion.source}: --clean repaired {len(repaired)} capture glitch(es) before retargeting ({listed}{more})")
    return fixed


def add_bvh_output_options(p: argparse.ArgumentParser) -> None:
    """The options that say how a BVH output is written (shared by ``retarget`` and ``batch``)."""
    p.add_argument("--up", choices=["Y", "Z", "y", "z"], default=None, help="BVH output up axis (default Y)")
    p.add_argument("--units", default=None, help="BVH output length unit (default m)")


class _RaisingParser(argparse.ArgumentParser):
    """An argument parser that raises :class:`OptionError` instead of exiting."""

    def error(self, message: str):  # type: ignore[override]
        raise OptionError(message)


def retarget_option_parser() -> argparse.ArgumentParser:
    """A parser of ``retarget``'s per-file options alone (:func:`add_retarget_options` and
    :func:`add_bvh_output_options`), raising :class:`OptionError` on a bad value; ``batch``
    reads a manifest's per-file options with it."""
    p = _RaisingParser(prog="retarget", add_help=False)
    add_retarget_options(p)
    add_bvh_output_options(p)
    return p


def config_from_args(args: argparse.Namespace):
    """The :class:`~physmocap.ik.config.RetargetConfig` the options of
    :func:`add_retarget_options` ask for, validated (nothing is read).

    Raises:
        OptionError: A frame range, iteration count or option value retarget refuses.
    """
    from ..ik.config import RetargetConfig
    from ..motion import MAX_FPS
    from ..options import check_frame_range
    from .solve import marker_solve_options

    check_frame_range(args.start, args.end)
    fps = getattr(args, "fps", None)
    if fps is not None and not (math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise OptionError(f"--fps: the frame rate must be a number in (0, {MAX_FPS:g}] frames/s, got {fps:g}")
    if getattr(args, "units", None) is not None:  # the BVH writer's unit, refused before the solve
        from ..sources.bvh import resolve_units

        try:
            resolve_units(args.units)
        except OptionError as exc:
            raise OptionError(f"--units: {exc}") from None
    options = {}
    if args.max_iterations is not None:
        if args.max_iterations < 1:
            raise OptionError("--max-iterations must be at least 1")
        options["max_iterations"] = args.max_iterations
    if args.no_floor:
        options["floor"] = False
    if args.no_velocity_limits:
        options["velocity_limits"] = False
    if getattr(args, "no_arm_branches", False):
        options["arm_branches"] = False
    if getattr(args, "no_ease_caps", False):
        options["ease_caps"] = False
    if getattr(args, "no_smooth_transitions", False):
        options["smooth_transitions"] = False
    if getattr(args, "no_self_collision", False):
        options["self_collision"] = False
    if args.no_plant:
        options["plant"] = False
    marker_solve_options(args)  # refused now, before anything is read
    return RetargetConfig().with_options(**options)


#: The options naming an input file besides the capture: argparse destination -> what it is.
OPTION_FILES = {
    "contacts": "contact label file",
    "source_map": "mapping file",
    "map": "mapping file",
    "marker_set": "marker set file",
}


def check_option_files(args: argparse.Namespace) -> None:
    """Refuse a file named by ``--contacts``, ``--source-map``, ``--map``, ``--marker-set``
    or ``--character`` (an MJCF path, not a bundled name) that is missing or unreadable,
    before the capture is read (:func:`~physmocap.fileio.check_readable`)."""
    from ..fileio import check_readable

    for dest, kind in OPTION_FILES.items():
        value = getattr(args, dest, None)
        if value:
            check_readable(value, kind)
    character = getattr(args, "character", None)
    if character:
        from ..models.character import character_file

        check_readable(character_file(character), "MJCF file")


WRITERS = {".bvh", ".npz", ".csv", ".mcap"}

#: Allocations of at least this many bytes get a mapping of their own (glibc's ``mallopt``).
LARGE_ALLOCATION_BYTES = 1 << 20


def return_large_frees_to_the_system() -> bool:
    """Serve allocations of :data:`LARGE_ALLOCATION_BYTES` or more (a long clip's per-joint
    arrays and a block's temporaries) with mappings of their own, unmapped when freed.

    glibc raises its threshold for that (``M_MMAP_THRESHOLD``, 128 KB at start) to the
    size of every large array freed, up to 32 MB, so a long retarget's megabyte-sized
    temporaries then come from the heap, whose freed middle is kept: measured on a
    5-minute clip, the peak RSS falls from 307 to 271 MB with a fixed threshold, and the
    plateau while tracking from 301 to 241 MB; outputs and time are unchanged.  False
    (nothing done) where the C library has no ``mallopt``.
    """
    import ctypes

    M_MMAP_THRESHOLD = -3
    try:
        return bool(ctypes.CDLL(None).mallopt(M_MMAP_THRESHOLD, LARGE_ALLOCATION_BYTES))
    except (AttributeError, OSError, TypeError):
        return False


def write_outputs(traj, outputs: list[Path], args: argparse.Namespace, quiet: bool = False) -> None:
    """Write ``traj`` to every path of ``outputs`` (the first in ``args.format``'s layout),
    all renamed into place together (:class:`~physmocap.fileio.OutputSet`): if one fails,
    none is written."""
    with OutputSet():
        _write_outputs(traj, outputs, args, quiet)


def _write_outputs(traj, outputs: list[Path], args: argparse.Namespace, quiet: bool) -> None:
    given = [f"--{name}" for name in ("up", "units") if getattr(args, name, None) is not None]
    if given and not any(out.suffix.lower() == ".bvh" for out in outputs):
        from ..errors import warn

        verb = "applies" if len(given) == 1 else "apply"
        warn(f"{' and '.join(given)} {verb} to BVH outputs only: ignored for {', '.join(str(o) for o in outputs)}")
    for k, out in enumerate(outputs):
        suffix = out.suffix.lower()
        layout = getattr(args, "format", "auto") if k == 0 else "auto"
        if layout == "robot-csv":
            from ..export.robot import write_robot_csv

            write_robot_csv(traj, out)
            if not quiet:
                announce(f"wrote {out.with_name(out.stem + '.joints.txt')}")
        elif layout == "robot-npz":
            from ..export.robot import write_robot_npz

            write_robot_npz(traj, out)
        elif suffix == ".bvh":
            from ..export.character_bvh import write_character_bvh

            write_character_bvh(traj, out, up=(args.up or "Y").upper(), units=args.units or "m")
        elif suffix == ".npz":
            from ..export.trajectory import write_trajectory_npz

            write_trajectory_npz(traj, out)
        elif suffix == ".csv":
            from ..export.trajectory import write_trajectory_csv

            write_trajectory_csv(traj, out)
        elif suffix == ".mcap":
            from ..export.mcap import write_trajectory_mcap

            write_trajectory_mcap(traj, out)
        if not quiet:
            announce(f"wrote {out}")


#: The options (argparse destinations) that concern marker inputs alone, unset: ``--marker-set``,
#: ``--joint-centres`` and the marker solve's (:func:`~physmocap.cli.solve.add_marker_solve_options`).
#: ``batch`` applies its own to its marker files only (:func:`physmocap.batch.job_options`).
MARKER_OPTIONS_UNSET: dict = {"marker_set": None, "joint_centres": False, "marker_max_iterations": None,
                              "marker_no_floor": False}


def marker_read_options(args: argparse.Namespace, path=None) -> dict:
    """What ``load_motion`` is told about a marker input by :data:`MARKER_OPTIONS_UNSET`'s
    options: ``marker_set``, ``solve`` False (``--joint-centres``) and ``solve_options`` (one
    validated :class:`~physmocap.markers.solve.MarkerSolveOptions`, as ``physmocap solve``
    builds it), for the file ``path`` (default: ``args.input``).

    Raises:
        OptionError: These options on an input that is not a marker file, or the solve's
            with ``--joint-centres`` (which skips the solve).
    """
    from ..sources.markers import MARKER_FILE_TYPES, is_marker_file
    from .solve import marker_solve_options

    marker_set = getattr(args, "marker_set", None)
    joint_centres = getattr(args, "joint_centres", False)
    solve_options = marker_solve_options(args)
    given = [flag for flag, value in (("--marker-set", marker_set), ("--joint-centres", joint_centres),
                                      ("--marker-max-iterations / --marker-no-floor", solve_options)) if value]
    if not given:
        return {}
    path = getattr(args, "input", None) if path is None else path
    if path is None or not is_marker_file(path):
        raise OptionError(f"{', '.join(given)}: for marker files only ({MARKER_FILE_TYPES})", path=path)
    if joint_centres and solve_options:
        raise OptionError("--marker-max-iterations and --marker-no-floor shape the actor's solve, which "
                          "--joint-centres skips", path=path)
    out: dict = {"marker_set": marker_set} if marker_set else {}
    if joint_centres:
        out["solve"] = False
    elif solve_options:
        out["solve_options"] = solve_options
    return out


def retarget_from_args(args: argparse.Namespace):
    """Load the input and the character and retarget with the options of
    :func:`add_retarget_options`; returns the trajectory.  A marker file is solved into the
    actor's skeleton first (:func:`physmocap.markers.motion.solved_motion`, calibrated and
    solved on the whole take; ``--start``/``--end`` then cut the retarget), or read as its
    joint centres with ``--joint-centres``."""
    from ..ik.retarget import retarget
    from ..models import load_character
    from ..sources import load_motion

    config = config_from_args(args)
    check_option_files(args)  # here, not in config_from_args: a batch manifest's missing file fails its own job
    read_opts = {"units": args.in_units} if args.in_units else {}
    if getattr(args, "in_up", None):
        from ..resources import resolve_input

        if resolve_input(args.input).suffix.lower() != ".bvh":  # "example" is the bundled BVH
            raise OptionError("--in-up: for BVH files only", path=args.input)
        read_opts["up"] = args.in_up.upper()
    read_opts.update(marker_read_options(args))
    from ..markers.motion import LegsNotCapturedError

    try:
        motion = load_motion(args.input, min_frames=1, **read_opts)
    except LegsNotCapturedError as exc:
        raise exc.for_character() from None  # an upper-body take: say what it means for the character
    motion = cleaned_source(motion, args)
    character = load_character(args.character, args.map)
    return retarget(
        motion,
        character,
        config,
        profile=args.profile,
        mapping=args.source_map,
        start=args.start,
        end=args.end,
        fps=args.fps,
        progress=False if args.quiet else None,
        contacts=args.contacts,
    )


def run(args: argparse.Namespace) -> int:
    outputs = [Path(args.output)] + [Path(x) for x in (args.qpos, args.csv) if x]
    wanted = {"robot-csv": ".csv", "robot-npz": ".npz"}.get(args.format)
    if wanted and outputs[0].suffix.lower() != wanted:
        raise OptionError(f"--format {args.format} writes a {wanted} file", path=outputs[0])
    for raw, out in zip([x for x in (args.output, args.qpos, args.csv) if x], outputs):
        check_writable(raw)  # as typed: a trailing separator is refused
        if out.suffix.lower() not in WRITERS:
            raise suffix_error(out, WRITERS)
    if args.report:
        check_writable(args.report, "report")
    check_not_input(outputs + [args.report, args.preview], [args.input, args.contacts, args.source_map, args.map])
    check_distinct(outputs + [args.report, args.preview])
    from ..options import check_frame_range

    check_frame_range(args.start, args.end)
    if args.plots:
        from ..plots import require_matplotlib
        from ..report import _check_plot_dir

        require_matplotlib()
        _check_plot_dir(args.plots)
    if args.preview:
        from ..render.output import check_output, require_imageio

        check_output(args.preview)
        require_imageio()
    return_large_frees_to_the_system()
    traj = retarget_from_args(args)
    with OutputSet():  # every file of the run renamed into place together, or none
        _write_all(traj, outputs, args)
    return 0


def _write_all(traj, outputs: list[Path], args: argparse.Namespace) -> None:
    write_outputs(traj, outputs, args, quiet=args.quiet)
    if args.report or args.plots:
        from ..report import emit_report

        emit_report(
            traj,
            traj.source_motion,
            traj.contacts,
            json_path=args.report,
            plots_dir=args.plots,
            joint_indices=traj.joint_indices,
            quiet=args.quiet,
        )
    if args.preview:
        from .preview import render_preview

        render_preview(traj, Path(args.preview), quiet=args.quiet)
