"""``physmocap preview``: render the character beside its source skeleton (MP4, GIF, PNG sheet)."""

from __future__ import annotations

import argparse
import sys
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
            ".npz written by retarget --qpos (give --source to draw its skeleton)."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file, 'example', or trajectory .npz")
    p.add_argument("-o", "--output", required=True, help="output: .mp4, .gif or .png (contact sheet)")
    p.add_argument("--size", default="640x480", help="image size per panel, WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--camera", default="side", help="side, front, back, top or AZIMUTH,ELEVATION in degrees "
                   "(azimuth relative to the character's initial heading)")
    p.add_argument("--layout", choices=["beside", "overlay"], default="beside", help="skeleton beside or over the character")
    p.add_argument("--frames", help="contact sheet: comma-separated source frame numbers (default: --count evenly spaced)")
    p.add_argument("--count", type=int, default=8, help="contact sheet: number of frames (default 8)")
    p.add_argument("--source", metavar="FILE", help="with a trajectory .npz: the source motion it was retargeted from")
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
    traj,
    output: Path,
    *,
    size: str = "640x480",
    camera: str = "side",
    layout: str = "beside",
    frames: list[int] | None = None,
    count: int = 8,
    quiet: bool = False,
) -> None:
    """Render ``traj`` (and its source, if it carries one) to ``output``."""
    from ..render.backend import ensure_backend
    from ..render.output import check_output, sheet_frames, write_sheet, write_video
    from ..render.scene import PreviewOptions, PreviewScene, parse_camera, parse_size
    from ..render.skeleton import source_skeleton

    out = check_output(output)
    w, h = parse_size(size)
    opts = PreviewOptions(width=w, height=h, camera=parse_camera(camera), layout=layout)
    if count < 1:
        raise OptionError("--count must be at least 1")
    ensure_backend()
    stats = getattr(traj, "stats", None) or {}
    contacts = stats.get("contacts")
    first = int(stats.get("source_start", 0))
    progress = False if quiet else None
    with PreviewScene(traj, source_skeleton(traj), getattr(contacts, "labels", None), opts) as scene:
        if out.suffix.lower() == ".png":
            write_sheet(scene, sheet_frames(traj.num_frames, count, frames, first), out, traj.fps, first, progress)
        else:
            write_video(scene, range(traj.num_frames), out, traj.fps, first, progress)
    print(f"wrote {out}", file=sys.stderr)


def _load(args: argparse.Namespace):
    """The trajectory to show: a saved .npz (with its source if given) or a fresh retarget."""
    if Path(args.input).suffix.lower() == ".npz":
        from ..report import load_trajectory

        traj = load_trajectory(args.input, args.character, args.map)
        if args.source:
            from ..ik.retarget import default_start, map_motion
            from ..ik.targets import build_targets
            from ..sources import load_motion

            motion = load_motion(args.source)
            start = default_start(motion) if args.start is None else int(args.start)
            motion = motion.slice_frames(start, min(motion.num_frames, start + traj.num_frames))
            if motion.num_frames != traj.num_frames:
                raise OptionError(
                    f"--source has {motion.num_frames} frames from frame {start} but the trajectory {traj.num_frames}; "
                    "pass --start as used for the retarget",
                    path=args.source,
                )
            joints = map_motion(motion, profile=args.profile, mapping=args.source_map)
            traj.targets = build_targets(motion, joints, traj.character)
            traj.stats.update(source_motion=motion, joint_indices=joints, source_start=start)
        return traj
    if args.source:
        raise OptionError("--source is for a trajectory .npz input; a motion file is its own source")
    from .retarget import retarget_from_args

    return retarget_from_args(args)


def run(args: argparse.Namespace) -> int:
    from ..render.output import check_output, require_imageio
    from ..render.scene import PreviewOptions, parse_camera, parse_size

    check_output(args.output)
    require_imageio()
    frames = _frame_list(args.frames)
    # every option is checked before the (possibly long) retarget
    w, h = parse_size(args.size)
    PreviewOptions(width=w, height=h, camera=parse_camera(args.camera), layout=args.layout)
    if args.count < 1:
        raise OptionError("--count must be at least 1")
    traj = _load(args)
    render_preview(
        traj, Path(args.output), size=args.size, camera=args.camera, layout=args.layout,
        frames=frames, count=args.count, quiet=args.quiet,
    )
    return 0
