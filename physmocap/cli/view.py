"""``physmocap view``: interactive playback of a trajectory or a retargeted source."""

from __future__ import annotations

import argparse

from .retarget import add_retarget_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="play a motion in MuJoCo's interactive viewer, the source skeleton beside the character",
        description=(
            "Open mujoco.viewer and loop the character's motion with the source skeleton drawn beside it "
            "(or overlaid); space pauses, the arrow keys step while paused. INPUT is a source (retargeted "
            "first, with the options of 'retarget') or a trajectory .npz. Needs a display; without one, "
            "use 'physmocap preview'."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file, 'example', or a trajectory .npz")
    add_retarget_arguments(p)
    p.add_argument("--overlay", action="store_true", help="draw the source skeleton over the character")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..preview.viewer import play, require_display
    from .preview import load_clip

    require_display(args.input)  # before spending time on a retarget
    play(load_clip(args), overlay=args.overlay)
    return 0
