"""One preview frame: the character, the source skeleton, a floor grid, planted contacts.

Rendered offscreen by ``mujoco.Renderer`` (:func:`.backend.ensure_backend` first).  The
character's geoms are recoloured by side (left blue, right red, as the skeleton's bones),
the skeleton is drawn as capsules (user geoms added to the scene), the floor is a plane
with a 0.5 m grid, and contact sites are marked green while their contact is labelled.
The camera follows the pelvis; its azimuth is taken relative to the character's heading
on the first frame, so "side" and "front" mean the same thing on every clip.  World
units are metres; images are ``(H, W, 3)`` uint8.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

from ..errors import OptionError
from .skeleton import LEFT, RIGHT, SourceSkeleton

__all__ = ["CameraView", "PreviewOptions", "PreviewScene", "add_skeleton", "parse_camera", "parse_size"]

LEFT_RGBA = np.array([0.25, 0.45, 0.95, 1.0], dtype=np.float32)
RIGHT_RGBA = np.array([0.90, 0.30, 0.25, 1.0], dtype=np.float32)
CENTRE_RGBA = np.array([0.75, 0.75, 0.72, 1.0], dtype=np.float32)
CONTACT_RGBA = np.array([0.2, 0.9, 0.3, 1.0], dtype=np.float32)
GRID_RGBA = np.array([0.35, 0.35, 0.38, 1.0], dtype=np.float32)
FLOOR_RGBA = np.array([0.16, 0.17, 0.19, 1.0], dtype=np.float32)
#: Opacity of the character in the ``overlay`` layout: the source skeleton drawn inside its
#: limbs shows through them.
OVERLAY_ALPHA = 0.35
#: Costly effects a preview does without (a scene's shadows, floor reflections and skybox).
_OFF_FLAGS = (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION, mujoco.mjtRndFlag.mjRND_SKYBOX)
#: Named views: (azimuth relative to the character's initial heading, elevation), degrees.
VIEWS = {"side": (-90.0, -12.0), "front": (180.0, -12.0), "back": (0.0, -12.0), "top": (-90.0, -89.0)}


@dataclass(frozen=True)
class CameraView:
    """Camera azimuth (relative to the character's initial heading) and elevation, degrees."""

    azimuth: float = VIEWS["side"][0]
    elevation: float = VIEWS["side"][1]


def parse_camera(text: str) -> CameraView:
    """``side``, ``front``, ``back``, ``top`` or ``AZIMUTH,ELEVATION`` in degrees."""
    t = text.strip().lower()
    if t in VIEWS:
        return CameraView(*VIEWS[t])
    try:
        az, el = (float(x) for x in t.split(","))
    except ValueError:
        raise OptionError(f"--camera: expected one of {', '.join(VIEWS)} or AZIMUTH,ELEVATION, got {text!r}") from None
    if not (np.isfinite(az) and np.isfinite(el)):
        raise OptionError(f"--camera: azimuth and elevation must be finite numbers of degrees, got {text!r}")
    if not -90.0 <= el <= 90.0:
        raise OptionError(f"--camera: elevation must be within -90..90 degrees, got {text!r}")
    return CameraView(az, el)


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels (16..4096 each) -> ``(width, height)``."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise OptionError(f"--size: expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise OptionError(f"--size: each side must be 16..4096 pixels, got {text!r}")
    return w, h


@dataclass(frozen=True)
class PreviewOptions:
    """How previews look.

    Attributes:
        width, height: Image size in pixels (per panel).
        camera: :class:`CameraView`.
        layout: ``"beside"`` (skeleton next to the character) or ``"overlay"``.
        distance: Camera distance in character heights.
        antialias: 4x multisampling: smoother edges, but about 2.7x the rendering time
            with a software OpenGL (Mesa llvmpipe), so off by default.
    """

    width: int = 640
    height: int = 480
    camera: CameraView = CameraView()
    layout: str = "beside"
    distance: float = 1.9
    antialias: bool = False

    def __post_init__(self) -> None:
        if self.layout not in ("beside", "overlay"):
            raise OptionError(f"layout must be 'beside' or 'overlay', got {self.layout!r}")
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise OptionError(f"image size must be 16..4096 pixels per side, got {self.width}x{self.height}")


def _body_sides(model: mujoco.MjModel, qpos0: np.ndarray) -> np.ndarray:
    """``(nbody,)`` side of every body from its rest position in the root's frame
    (characters face +X, left is +Y): beyond 1.5 % of the body's height either way."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos0
    mujoco.mj_kinematics(model, data)
    root = 1 if model.nbody > 1 else 0
    R = data.xmat[root].reshape(3, 3)
    y = (data.xpos - data.xpos[root]) @ R[:, 1]
    tall = float(np.ptp(data.xpos[:, 2])) or 1.0
    side = np.zeros(model.nbody, dtype=int)
    side[y > 0.015 * tall] = LEFT
    side[y < -0.015 * tall] = RIGHT
    return side


def _add_geom(scene: mujoco.MjvScene, kind: int, size, pos, rgba, mat=None) -> mujoco.MjvGeom | None:
    if scene.ngeom >= scene.maxgeom:
        return None
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(
        g, kind, np.asarray(size, dtype=float), np.asarray(pos, dtype=float),
        np.eye(3).ravel() if mat is None else np.asarray(mat, dtype=float).ravel(), np.asarray(rgba, dtype=np.float32),
    )
    scene.ngeom += 1
    return g


def _add_connector(scene: mujoco.MjvScene, kind: int, width: float, a, b, rgba) -> None:
    g = _add_geom(scene, kind, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], rgba)
    if g is not None:
        mujoco.mjv_connector(g, kind, width, np.asarray(a, dtype=float), np.asarray(b, dtype=float))


class PreviewScene:
    """Renders frames of one trajectory (and its source skeleton, if any).

    Args:
        traj: The character's :class:`~physmocap.trajectory.Trajectory`.
        skeleton: The :class:`~.skeleton.SourceSkeleton` over the same frames, or None.
        contacts: Canonical contact label -> ``(F,)`` bool (``left_heel`` ...), or None.
        options: :class:`PreviewOptions`.
    """

    def __init__(self, traj, skeleton: SourceSkeleton | None, contacts, options: PreviewOptions) -> None:
        self.traj = traj
        self.skeleton = skeleton
        self.options = opt = options
        ch = traj.character
        model = copy.deepcopy(ch.model)
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), opt.width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), opt.height)
        model.vis.quality.offsamples = 4 if opt.antialias else 0
        side = _body_sides(model, ch.rest_qpos)
        for g in range(model.ngeom):
            s = side[model.geom_bodyid[g]]
            rgba = LEFT_RGBA if s == LEFT else RIGHT_RGBA if s == RIGHT else CENTRE_RGBA
            model.geom_rgba[g] = rgba if model.geom_rgba[g][3] > 0 else model.geom_rgba[g]
        if skeleton is not None and opt.layout == "overlay":  # see-through, the skeleton inside it visible
            model.geom_rgba[:, 3] = np.minimum(model.geom_rgba[:, 3], OVERLAY_ALPHA)
        self.model = model
        self.data = mujoco.MjData(model)
        self.renderer = mujoco.Renderer(model, opt.height, opt.width, max_geom=model.ngeom + 4000)
        self.height_m = float(getattr(ch, "height", 1.7) or 1.7)
        self.sites: list[tuple[int, str]] = []
        for s_name in ("left", "right"):
            for k, site in enumerate(ch.contacts.get(s_name, ())):
                self.sites.append((model.site(site).id, f"{s_name}_{'heel' if k == 0 else 'toe'}"))
        self.contacts = contacts
        self.root = 1 if model.nbody > 1 else 0
        self.heading = self._initial_heading()
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.azimuth = self.heading + opt.camera.azimuth
        self.camera.elevation = opt.camera.elevation
        self.camera.distance = opt.distance * self.height_m
        az = np.radians(self.camera.azimuth)
        # screen right for a camera looking along (cos az, sin az)
        self.right = np.array([np.sin(az), -np.cos(az), 0.0])
        self.offset = self.right * (0.75 * self.height_m) if (skeleton is not None and opt.layout == "beside") else np.zeros(3)
        self.hidden = mujoco.MjvOption()
        self.hidden.geomgroup[:] = 0
        self.hidden.sitegroup[:] = 0

    def _initial_heading(self) -> float:
        """Heading (degrees about +Z) the character faces on the first frame.

        Facing is :math:`(l - r) \\times \\hat z` from the left and right hip joints, which
        a bent torso does not tilt; without both hips mapped, the root body's rotation
        from the rest pose (facing +X) applied to +X.
        """
        ch, model, data = self.traj.character, self.model, self.data
        data.qpos[:] = ch.rest_qpos
        mujoco.mj_kinematics(model, data)
        rest = data.xmat[self.root].reshape(3, 3).copy()
        self.rest_root_z = float(data.xpos[self.root][2])
        data.qpos[:] = self.traj.qpos[0]
        mujoco.mj_kinematics(model, data)
        hips = [getattr(ch, "tracked", {}).get(f"{s}_hip") for s in ("left", "right")]
        if all(h is not None for h in hips):
            l, r = (h.position(model, data) for h in hips)
            forward = np.cross(l - r, [0.0, 0.0, 1.0])
        else:
            forward = data.xmat[self.root].reshape(3, 3) @ rest.T @ np.array([1.0, 0.0, 0.0])
        return float(np.degrees(np.arctan2(forward[1], forward[0])))

    def close(self) -> None:
        self.renderer.close()

    def __enter__(self) -> "PreviewScene":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def render(self, t: int, character: bool = True, source: bool = True) -> np.ndarray:
        """Image ``(H, W, 3)`` of frame ``t``: the character and/or the source skeleton."""
        self.data.qpos[:] = self.traj.qpos[t]
        mujoco.mj_kinematics(self.model, self.data)
        pelvis = self.data.xpos[self.root].copy()
        show_skeleton = source and self.skeleton is not None
        # follow the pelvis; upwards too (jumps), not down (a crouch keeps the feet in view)
        self.camera.lookat[:] = [pelvis[0], pelvis[1], 0.5 * self.height_m + max(0.0, pelvis[2] - self.rest_root_z)]
        both = character and show_skeleton and self.options.layout == "beside"
        self.camera.distance = self.options.distance * self.height_m * (1.4 if both else 1.0)
        if character and show_skeleton:
            self.camera.lookat[:] += 0.5 * self.offset
        elif show_skeleton:
            self.camera.lookat[:] += self.offset
        self.renderer.update_scene(self.data, camera=self.camera, scene_option=None if character else self.hidden)
        scene = self.renderer.scene
        for flag in _OFF_FLAGS:
            scene.flags[flag] = 0
        self._floor(scene, pelvis)
        if character:
            self._contacts(scene, t)
        if show_skeleton:
            self._skeleton(scene, t)
        return self.renderer.render()

    def _floor(self, scene: mujoco.MjvScene, centre: np.ndarray) -> None:
        half = 4.0 * self.height_m
        c = np.round(centre[:2] / 0.5) * 0.5
        _add_geom(scene, mujoco.mjtGeom.mjGEOM_BOX, [half, half, 0.002], [c[0], c[1], -0.003], FLOOR_RGBA)
        for k in np.arange(-half, half + 1e-9, 0.5):
            _add_connector(scene, mujoco.mjtGeom.mjGEOM_LINE, 1.0, [c[0] + k, c[1] - half, 0.0], [c[0] + k, c[1] + half, 0.0], GRID_RGBA)
            _add_connector(scene, mujoco.mjtGeom.mjGEOM_LINE, 1.0, [c[0] - half, c[1] + k, 0.0], [c[0] + half, c[1] + k, 0.0], GRID_RGBA)

    def _contacts(self, scene: mujoco.MjvScene, t: int) -> None:
        if self.contacts is None:
            return
        r = 0.018 * self.height_m
        for sid, label in self.sites:
            lab = self.contacts.get(label)
            if lab is not None and bool(lab[t]):
                _add_geom(scene, mujoco.mjtGeom.mjGEOM_SPHERE, [r, r, r], self.data.site_xpos[sid], CONTACT_RGBA)

    def _skeleton(self, scene: mujoco.MjvScene, t: int) -> None:
        assert self.skeleton is not None
        add_skeleton(scene, self.skeleton, t, 0.012 * self.height_m, self.offset)


def add_skeleton(scene: mujoco.MjvScene, sk: SourceSkeleton, t: int, width: float, offset=(0.0, 0.0, 0.0)) -> None:
    """Frame ``t`` of the source skeleton as capsules of radius ``width`` (m), coloured by
    side, shifted by ``offset`` (m); bones with a lost or coincident end are skipped."""
    P = sk.positions[t] + np.asarray(offset, dtype=float)
    for a, b in sk.bones:
        if not (np.all(np.isfinite(P[a])) and np.all(np.isfinite(P[b]))) or np.linalg.norm(P[b] - P[a]) < 1e-6:
            continue
        s = sk.side[b]
        rgba = LEFT_RGBA if s == LEFT else RIGHT_RGBA if s == RIGHT else CENTRE_RGBA
        _add_connector(scene, mujoco.mjtGeom.mjGEOM_CAPSULE, width, P[a], P[b], rgba)
