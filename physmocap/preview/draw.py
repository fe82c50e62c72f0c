"""Decorations added to a :class:`mujoco.MjvScene`: the source skeleton as capsules,
a floor with a grid, planted contacts, and left/right colours on the character.

Used by the offscreen renderer and by the interactive viewer (``user_scn``), so
both draw the same thing.  Lengths in metres.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from .clip import CENTRE, LEFT, RIGHT, SourceSkeleton, character_sides

__all__ = ["SIDE_RGBA", "coloured_model", "draw_floor", "draw_planted", "draw_skeleton"]

#: Colour of each side, the same on the character and on the source skeleton.
SIDE_RGBA = {
    CENTRE: np.array([0.85, 0.85, 0.82, 1.0], dtype=np.float32),
    LEFT: np.array([0.25, 0.5, 1.0, 1.0], dtype=np.float32),
    RIGHT: np.array([1.0, 0.35, 0.2, 1.0], dtype=np.float32),
}
PLANTED_RGBA = np.array([0.1, 0.95, 0.3, 1.0], dtype=np.float32)
FLOOR_RGBA = np.array([0.32, 0.34, 0.38, 1.0], dtype=np.float32)
GRID_RGBA = np.array([0.55, 0.58, 0.62, 1.0], dtype=np.float32)
_EYE = np.eye(3).ravel()
_ZERO = np.zeros(3)


def coloured_model(character) -> mujoco.MjModel:
    """A copy of the character's model with its left geoms blue and right geoms red
    (materials dropped on those geoms so the colour shows)."""
    model = copy.deepcopy(character.model)
    sides = character_sides(character)
    for g in range(model.ngeom):
        side = int(sides[model.geom_bodyid[g]])
        if side != CENTRE:
            model.geom_rgba[g] = SIDE_RGBA[side]
            model.geom_matid[g] = -1
    return model


def _add(scene: mujoco.MjvScene, gtype: int, size, pos, rgba) -> mujoco.MjvGeom | None:
    """Append one geom to ``scene``; None when the scene is full."""
    if scene.ngeom >= scene.maxgeom:
        return None
    geom = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(geom, gtype, np.asarray(size, float), np.asarray(pos, float), _EYE, rgba)
    scene.ngeom += 1
    return geom


def _connect(scene: mujoco.MjvScene, gtype: int, width: float, a: np.ndarray, b: np.ndarray, rgba) -> None:
    geom = _add(scene, gtype, _ZERO, _ZERO, rgba)
    if geom is not None:
        mujoco.mjv_connector(geom, gtype, width, a, b)


def draw_skeleton(scene: mujoco.MjvScene, skeleton: SourceSkeleton, frame: int, radius: float, offset) -> None:
    """Bones (capsules) and joints (spheres) of one frame, shifted by ``offset`` (m)."""
    pts = skeleton.positions[frame] + np.asarray(offset, dtype=float)
    ok = np.all(np.isfinite(pts), axis=1)
    for j, p in enumerate(skeleton.parents):
        if not ok[j]:
            continue
        rgba = SIDE_RGBA[int(skeleton.sides[j])]
        _add(scene, mujoco.mjtGeom.mjGEOM_SPHERE, (1.4 * radius, 0, 0), pts[j], rgba)
        if p >= 0 and ok[p] and np.linalg.norm(pts[j] - pts[p]) > 1e-6:
            _connect(scene, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, pts[p], pts[j], rgba)


def draw_floor(scene: mujoco.MjvScene, centre, half: float, spacing: float, plane: bool = True) -> None:
    """A floor at z = 0 around ``centre`` (x, y): a plane (unless the model has one)
    and grid lines every ``spacing`` metres, fixed to the world so motion shows."""
    cx, cy = float(centre[0]), float(centre[1])
    if plane:
        _add(scene, mujoco.mjtGeom.mjGEOM_PLANE, (half, half, spacing), (cx, cy, 0.0), FLOOR_RGBA)
    n = int(np.ceil(half / spacing))
    x0, y0 = np.round(cx / spacing) * spacing, np.round(cy / spacing) * spacing
    z = 1e-3
    for k in range(-n, n + 1):
        x, y = x0 + k * spacing, y0 + k * spacing
        _connect(scene, mujoco.mjtGeom.mjGEOM_LINE, 1.0, np.array([x, y0 - half, z]), np.array([x, y0 + half, z]), GRID_RGBA)
        _connect(scene, mujoco.mjtGeom.mjGEOM_LINE, 1.0, np.array([x0 - half, y, z]), np.array([x0 + half, y, z]), GRID_RGBA)


def draw_planted(scene: mujoco.MjvScene, points: np.ndarray, radius: float) -> None:
    """A flat green disc on the floor under each planted contact point ``(K, 3)``."""
    for p in np.asarray(points, dtype=float).reshape(-1, 3):
        _add(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, (radius, 2e-3, 0), (p[0], p[1], 2e-3), PLANTED_RGBA)
