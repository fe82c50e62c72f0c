"""``physmocap preview``: render the character beside its source skeleton (MP4, GIF, PNG sheet)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import OptionError


def register(sub: argparse._SubParsersAction) -> None:
    from .retarget import add_retarget_options

    p = sub.add_parser(
        "preview",
        help="render a retarget beside its source skeleton (.mp4, .gif, .png sheet)",
        description=(
            "Render the character and the source skeleton offscreen with MuJoCo's renderer. INPUT is a "
            "motion file (retargeted first, with the same options as retarget), 'example', or a trajectory "
            ".npz written by retarget --qpos (give --source to draw its skeleton). Videos play at --fps "
            "(a source is retargeted at that rate; a trajectory's frames are picked at it), by default the "
            "clip's rate up to 30 frames per second."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file, 'example', or trajectory .npz")
    p.add_argument("-o", "--output", required=True, help="output: .mp4, .gif or .png (contact sheet)")
    p.add_argument("--size", default="640x480", help="image size per panel, WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--camera", default="side", help="side, front, back, top or AZIMUTH,ELEVATION in degrees "
                   "(azimuth relative to the character's initial heading; a negative one as --camera=-60,-15)")
    p.add_argument("--layout", choices=["beside", "overlay"], default="beside", help="skeleton beside or over the character")
    p.add_argument("--frames", help="contact sheet: comma-separated source frame numbers (default: --count evenly spaced)")
    p.add_argument("--count", type=int, default=8, help="contact sheet: number of frames (default 8)")
    p.add_argument("--source", metavar="FILE", help="with a trajectory .npz: the source motion it was retargeted from")
    p.add_argument("--antialias", action="store_true", help="4x multisampling: smoother edges, about 2.7x slower")
    add_retarget_options(p)
    p.set_defaults(func=run)


def _frame_list(text: str | None) -> list[int] | None:
    if not text:
        return None
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise OptionError(f"--frames: expected comma-separated frame numbers, got {text!r}") from None


def render_preview(
    source,
    output: Path,
    options=None,
    *,
    frames: list[int] | None = None,
    count: int = 8,
    fps: float | None = None,
    quiet: bool = False,
) -> None:
    """Render a retargeted trajectory (or a :class:`~physmocap.render.source.PreviewInput`)
    to ``output`` with :class:`~physmocap.render.scene.PreviewOptions` ``options``."""
    from ..render.backend import ensure_backend
    from ..render.output import (check_output, check_sheet, check_size, sheet_frames, sheet_rows, video_frames, write_sheet,
                                 write_video)
    from ..render.scene import PreviewOptions, PreviewScene
    from ..render.source import PreviewInput, preview_input

    out = check_output(output)
    options = options or PreviewOptions()
    check_size(out, options.width, options.height)
    if count < 1:
        raise OptionError("--count must be at least 1")
    inp = source if isinstance(source, PreviewInput) else preview_input(source)
    traj = inp.traj
    ensure_backend()
    progress = False if quiet else None
    sheet = sheet_frames(traj.num_frames, count, frames, inp.first) if out.suffix.lower() == ".png" else None
    if sheet is not None:
        check_sheet(out, len(sheet), options.width, options.height,
                    sheet_rows(options.layout == "overlay", inp.skeleton is not None))
    with PreviewScene(traj, inp.skeleton, inp.contacts, options) as scene:
        if sheet is not None:
            write_sheet(scene, sheet, out, inp.first, progress)
        else:
            shown, rate = video_frames(traj.num_frames, traj.fps, fps)
            write_video(scene, shown, out, rate, inp.first, progress)
    if not quiet:
        from ..fileio import announce

        announce(f"wrote {out}")


def _source_start(args: argparse.Namespace, traj) -> int | None:
    """The source frame a saved trajectory starts at: ``--start`` if given, else the one the
    file records (``source_start``, written by ``retarget --qpos``), else None (guessed as a
    retarget would, for a file without it)."""
    if args.start is not None:
        return args.start
    import numpy as np

    with np.load(args.input, allow_pickle=False) as data:
        return int(traj.source_start) if "source_start" in data.files else None


def _load(args: argparse.Namespace):
    """The :class:`~physmocap.render.source.PreviewInput` to show: a saved .npz (with its
    source if given) or a fresh retarget."""
    from ..render.source import preview_input, preview_input_with_source

    if Path(args.input).suffix.lower() == ".npz":
        from ..report import load_trajectory

        traj = load_trajectory(args.input, args.character, args.map)
        if not args.source:
            return preview_input(traj)
        from ..sources import load_motion
        from .retarget import cleaned_source

        source = cleaned_source(load_motion(args.source, min_frames=1), args)
        return preview_input_with_source(traj, source, _source_start(args, traj), args.profile, args.source_map)
    if args.source:
        raise OptionError("--source is for a trajectory .npz input; a motion file is its own source")
    from .retarget import retarget_from_args

    return preview_input(retarget_from_args(args))


def options_from_args(args: argparse.Namespace):
    """:class:`~physmocap.render.scene.PreviewOptions` from the command line (checked)."""
    from ..render.scene import PreviewOptions, parse_camera, parse_size

    w, h = parse_size(args.size)
    return PreviewOptions(width=w, height=h, camera=parse_camera(args.camera), layout=args.layout, antialias=args.antialias)


def run(args: argparse.Namespace) -> int:
    from ..render.output import check_output, check_size, require_imageio, video_frames
    from .retarget import check_option_files

    check_output(args.output)
    require_imageio()
    check_option_files(args)  # a saved .npz input does not pass through retarget's checks
    # every option is checked before the (possibly long) retarget
    frames = _frame_list(args.frames)
    options = options_from_args(args)
    check_size(Path(args.output), options.width, options.height)
    if args.count < 1:
        raise OptionError("--count must be at least 1")
    if args.fps is not None:
        video_frames(1, 1.0, args.fps)
    render_preview(
        _load(args), Path(args.output), options, frames=frames, count=args.count, fps=args.fps, quiet=args.quiet
    )
    return 0
