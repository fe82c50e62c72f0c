"""Offscreen frames of a :class:`~physmocap.preview.clip.PreviewClip` with :class:`mujoco.Renderer`.

Each image shows the character and the source skeleton (beside it, offset to
the camera's right by 0.8 character heights, or overlaid), on a floor with a
grid, planted contacts as green discs, and the source frame number and time
written in the top-left corner.  Shadows, reflections and the skybox are off:
they cost more than the rest together with a software OpenGL.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..errors import OptionError
from .camera import CameraSpec, beside_offset, follow, heading_degrees
from .clip import PreviewClip
from .draw import coloured_model, draw_floor, draw_planted, draw_skeleton
from .gl import make_renderer

__all__ = ["ClipRenderer", "RenderOptions"]

_OFF_FLAGS = (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION, mujoco.mjtRndFlag.mjRND_SKYBOX)


@dataclass(frozen=True)
class RenderOptions:
    """How frames look.

    Attributes:
        width, height: Image size in pixels.
        camera: View direction (:class:`~physmocap.preview.camera.CameraSpec`).
        overlay: Draw the source skeleton on the character instead of beside it.
        label: Write the frame number and time on each image.
        antialias: Multisample anti-aliasing (4 samples): smoother edges, about
            3x slower with a software OpenGL.
    """

    width: int = 640
    height: int = 480
    camera: CameraSpec = field(default_factory=CameraSpec)
    overlay: bool = False
    label: bool = True
    antialias: bool = False

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and 16 <= v <= 4096):
                raise OptionError(f"image {name} must be a whole number of pixels in [16, 4096], got {v!r}")


class ClipRenderer:
    """Renders frames of one clip; ``frame(i)`` returns an ``(H, W, 3)`` uint8 image."""

    def __init__(self, clip: PreviewClip, options: RenderOptions | None = None) -> None:
        self.clip = clip
        self.options = opt = options or RenderOptions()
        character = clip.trajectory.character
        self.model = coloured_model(character)
        self.model.vis.quality.offsamples = 4 if opt.antialias else 0
        self.data = mujoco.MjData(self.model)
        self._renderer = make_renderer(self.model, opt.width, opt.height)
        self._has_plane = bool(np.any(self.model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE))
        self.size = float(character.height)
        qpos = clip.trajectory.qpos
        heading = heading_degrees(character, qpos[0])
        az, el = opt.camera.angles(heading)
        self.camera = cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.azimuth, cam.elevation = az, el
        beside = clip.skeleton is not None and not opt.overlay
        self.offset = beside_offset(az, self.size) if beside else np.zeros(3)
        adr = int(self.model.jnt_qposadr[self.model.joint(character.root_joint).id])
        roots = qpos[:, adr : adr + 3]  # a free joint's position is its body's world position
        # follow the pelvis, vertically too (jumps), keeping the standing body in frame
        self._lookat = follow(roots + 0.5 * self.offset, clip.trajectory.fps)
        self._lookat[:, 2] += 0.5 * self.size - character.rest_qpos[adr + 2]
        span = (0.75 if beside else 0.4) * self.size  # half the width to show, m
        half = max(0.62 * self.size, span / (opt.width / opt.height))
        cam.distance = half / math.tan(math.radians(self.model.vis.global_.fovy) / 2)
        self._planted = [(self.model.site(s).id, on) for s, on in clip.planted.items()]

    def frame(self, i: int, character: bool = True, skeleton: bool = True) -> np.ndarray:
        """Image of trajectory frame ``i``; ``character`` / ``skeleton`` choose what is drawn."""
        model, data, scene = self.model, self.data, self._renderer.scene
        data.qpos[:] = self.clip.trajectory.qpos[i]
        mujoco.mj_kinematics(model, data)
        self.camera.lookat[:] = self._lookat[i]
        self._renderer.update_scene(data, self.camera)
        for flag in _OFF_FLAGS:
            scene.flags[flag] = 0
        if not character:
            scene.ngeom = 0
        draw_floor(scene, self._lookat[i], half=3.0 * self.size, spacing=0.5, plane=not (character and self._has_plane))
        if character:
            pts = [data.site_xpos[s] for s, on in self._planted if on[i]]
            draw_planted(scene, np.array(pts), radius=0.035 * self.size)
        if skeleton and self.clip.skeleton is not None:
            draw_skeleton(scene, self.clip.skeleton, i, radius=0.012 * self.size, offset=self.offset)
        image = self._renderer.render()
        return self._label(image, i) if self.options.label else image

    def _label(self, image: np.ndarray, i: int) -> np.ndarray:
        from .text import write_text

        n = int(self.clip.frame_numbers[i])
        return write_text(image, f"frame {n}  {n / self.clip.source_fps:.2f} s")

    def close(self) -> None:
        self._renderer.close()

    def __enter__(self) -> "ClipRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
