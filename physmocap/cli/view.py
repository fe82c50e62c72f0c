"""``physmocap view``: interactive playback in ``mujoco.viewer`` with the source skeleton overlaid."""

from __future__ import annotations

import argparse
import os
import time

from ..errors import OptionError


def register(sub: argparse._SubParsersAction) -> None:
    from .retarget import add_retarget_options

    p = sub.add_parser(
        "view",
        help="play a retarget interactively (needs a display; see preview for files)",
        description=(
            "Open MuJoCo's viewer and play the character with the source skeleton overlaid; space "
            "pauses. INPUT is a motion file (retargeted first), 'example', or a trajectory .npz."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion file, 'example', or trajectory .npz")
    p.add_argument("--source", metavar="FILE", help="with a trajectory .npz: the source motion it was retargeted from")
    p.add_argument("--loop", action="store_true", help="play in a loop until the window closes")
    add_retarget_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) and os.name != "nt":
        raise OptionError("no display here: physmocap view needs a window; render a file instead with physmocap preview INPUT -o out.mp4")
    import mujoco
    import mujoco.viewer

    from ..render.scene import add_skeleton
    from .preview import _load
    from .retarget import check_option_files

    check_option_files(args)
    inp = _load(args)
    traj, sk = inp.traj, inp.skeleton
    model = traj.character.model
    data = mujoco.MjData(model)
    paused = {"on": False}

    def key(code: int) -> None:
        if code == 32:  # space
            paused["on"] = not paused["on"]

    with mujoco.viewer.launch_passive(model, data, key_callback=key) as viewer:
        t = 0
        while viewer.is_running():
            start = time.perf_counter()
            data.qpos[:] = traj.qpos[t]
            mujoco.mj_forward(model, data)
            with viewer.lock():
                viewer.user_scn.ngeom = 0
                if sk is not None:
                    add_skeleton(viewer.user_scn, sk, t, 0.012 * float(getattr(traj.character, "height", 1.7)))
            viewer.sync()
            if not paused["on"]:
                t += 1
                if t >= traj.num_frames:
                    if not args.loop:
                        break
                    t = 0
            time.sleep(max(0.0, 1.0 / traj.fps - (time.perf_counter() - start)))
    return 0
