"""Interactive playback in :mod:`mujoco.viewer`: the character with the source
skeleton drawn beside it (or overlaid) as extra geoms; space pauses and resumes,
the arrow keys step one frame while paused."""

from __future__ import annotations

import time

import mujoco
import numpy as np

from .camera import VIEWS, beside_offset, heading_degrees
from .clip import PreviewClip
from .draw import coloured_model, draw_planted, draw_skeleton
from .gl import BackendError, has_display

__all__ = ["play", "require_display"]

_SPACE, _RIGHT, _LEFT = 32, 262, 263


class _Clock:
    """Playback position in frames: advances with wall time unless paused."""

    def __init__(self, fps: float, frames: int) -> None:
        self.fps, self.frames = fps, frames
        self.paused = False
        self.position = 0.0
        self._last = time.perf_counter()

    def key(self, keycode: int) -> None:
        if keycode == _SPACE:
            self.paused = not self.paused
        elif self.paused and keycode in (_LEFT, _RIGHT):
            self.position = (int(self.position) + (1 if keycode == _RIGHT else -1)) % self.frames

    def frame(self) -> int:
        now = time.perf_counter()
        if not self.paused:
            self.position = (self.position + (now - self._last) * self.fps) % self.frames
        self._last = now
        return int(self.position)


def require_display(input_name: str = "INPUT") -> None:
    """Fail with one line (suggesting ``physmocap preview``) when no window can be opened."""
    if not has_display():
        raise BackendError(
            "no display to open the viewer on (DISPLAY is not set); render a file instead: "
            f"physmocap preview {input_name} -o preview.mp4"
        )


def play(clip: PreviewClip, overlay: bool = False) -> None:
    """Open the viewer and loop the clip until the window is closed."""
    require_display()
    import mujoco.viewer

    character = clip.trajectory.character
    model = coloured_model(character)
    data = mujoco.MjData(model)
    size = float(character.height)
    heading = heading_degrees(character, clip.trajectory.qpos[0])
    offset = np.zeros(3) if overlay or clip.skeleton is None else beside_offset(heading + VIEWS["side"][0], size)
    planted = [(model.site(s).id, on) for s, on in clip.planted.items()]
    clock = _Clock(clip.trajectory.fps, clip.num_frames)
    with mujoco.viewer.launch_passive(model, data, key_callback=clock.key) as viewer:
        while viewer.is_running():
            i = clock.frame()
            with viewer.lock():
                data.qpos[:] = clip.trajectory.qpos[i]
                mujoco.mj_forward(model, data)
                scene = viewer.user_scn
                scene.ngeom = 0
                if clip.skeleton is not None:
                    draw_skeleton(scene, clip.skeleton, i, radius=0.012 * size, offset=offset)
                draw_planted(scene, np.array([data.site_xpos[s] for s, on in planted if on[i]]), 0.035 * size)
            viewer.sync()
            time.sleep(0.5 / max(clip.trajectory.fps, 1.0))
