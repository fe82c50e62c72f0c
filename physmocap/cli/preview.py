"""``physmocap preview``: render the character beside the source skeleton (MP4, GIF, PNG sheet)."""

from __future__ import annotations

import argparse
import sys

from ..errors import OptionError
from .retarget import add_retarget_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "preview",
        help="render the retargeted character beside the source skeleton (.mp4, .gif, .png sheet)",
        description=(
            "Render a motion offscreen with MuJoCo: the character and, beside it (or overlaid), the source "
            "skeleton, left side blue and right side red on both, planted contacts green, a camera that "
            "follows the pelvis. INPUT is a source (retargeted first, with the options of 'retarget'; "
            "'example' is the bundled walk) or a trajectory .npz from 'retarget --qpos'. A .png output is "
            "a contact sheet: the character row above the source row. Needs physmocap[render] and an "
            "OpenGL backend (EGL or OSMesa without a display)."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file, 'example', or a trajectory .npz")
    p.add_argument("-o", "--output", required=True, help="output: .mp4, .gif or .png (contact sheet)")
    add_retarget_arguments(p)
    add_render_arguments(p)
    p.set_defaults(func=run)


def add_render_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fps", type=float, help="video frame rate (default: the clip's rate, at most 30)")
    p.add_argument("--size", default=None, help="image (sheet: tile) size WxH in pixels (default 640x480; sheet 240x320)")
    p.add_argument("--camera", default="side", help="side, front, back, top (relative to the actor's facing) or AZ,EL degrees")
    p.add_argument("--overlay", action="store_true", help="draw the source skeleton over the character, not beside it")
    p.add_argument("--count", type=int, default=8, help="contact sheet: number of evenly spaced frames (default 8)")
    p.add_argument("--frames", help="contact sheet: source frame numbers, e.g. 10,50,120")
    p.add_argument("--antialias", action="store_true", help="smooth edges (4x multisampling; slower)")


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise OptionError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 640x480") from None
    return w, h


def parse_frames(text: str | None) -> list[int] | None:
    if not text:
        return None
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise OptionError(f"--frames {text!r}: expected frame numbers separated by commas, e.g. 10,50,120") from None


def load_clip(args: argparse.Namespace):
    """The :class:`~physmocap.preview.clip.PreviewClip` of INPUT: a trajectory NPZ, or a retargeted source."""
    from ..preview.clip import is_trajectory_file, retarget_clip, trajectory_clip

    if is_trajectory_file(args.input):
        return trajectory_clip(args.input, args.character).between(args.start, args.end)
    from .retarget import retarget_inputs

    motion, character, options = retarget_inputs(args)
    return retarget_clip(motion, character, **options)


def run(args: argparse.Namespace) -> int:
    from ..preview.camera import CameraSpec
    from ..preview.output import check_preview_path, write_preview
    from ..preview.render import RenderOptions

    out = check_preview_path(args.output)
    sheet = out.suffix.lower() == ".png"
    width, height = parse_size(args.size or ("240x320" if sheet else "640x480"))
    options = RenderOptions(width, height, CameraSpec.parse(args.camera), args.overlay, True, args.antialias)
    frames = parse_frames(args.frames)
    clip = load_clip(args)
    write_preview(clip, out, options, fps=args.fps, count=args.count, frames=frames, progress=False if args.quiet else None)
    print(f"wrote {out}", file=sys.stderr)
    return 0
