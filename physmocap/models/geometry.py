"""Vertical extent of geoms and lowest points: what "standing on the floor" means.

For a geom with world position ``p`` and rotation ``R`` (columns = geom axes)
the lowest and highest world heights are ``p_z -/+ e`` with

* sphere radius ``r``: ``e = r``;
* capsule radius ``r``, half-length ``h`` along its local z: ``e = r + h |R_zz|``;
* cylinder: ``e = h |R_zz| + r sqrt(1 - R_zz^2)``;
* box half-sizes ``a``: ``e = sum_i a_i |R_zi|``;
* ellipsoid semi-axes ``a``: ``e = sqrt(sum_i (a_i R_zi)^2)``;
* mesh: the exact extremes of its vertices; planes and height fields are
  world scenery and are skipped.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["geom_z_extent", "character_geoms", "is_visual_only", "lowest_z", "highest_z"]


def geom_z_extent(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> tuple[float, float]:
    """``(lowest z, highest z)`` in metres of geom ``geom`` in the pose of ``data``.

    ``mj_kinematics`` (or ``mj_forward``) must have been run on ``data``.
    """
    gtype = int(model.geom_type[geom])
    size = model.geom_size[geom]
    pz = float(data.geom_xpos[geom][2])
    rz = data.geom_xmat[geom].reshape(3, 3)[2]  # third row: z components of the geom axes
    G = mujoco.mjtGeom
    if gtype == G.mjGEOM_SPHERE:
        e = size[0]
    elif gtype == G.mjGEOM_CAPSULE:
        e = size[0] + size[1] * abs(rz[2])
    elif gtype == G.mjGEOM_CYLINDER:
        e = size[1] * abs(rz[2]) + size[0] * np.sqrt(max(0.0, 1.0 - rz[2] ** 2))
    elif gtype == G.mjGEOM_BOX:
        e = float(np.abs(rz) @ size)
    elif gtype == G.mjGEOM_ELLIPSOID:
        e = float(np.sqrt(np.sum((size * rz) ** 2)))
    elif gtype == G.mjGEOM_MESH:
        mesh = int(model.geom_dataid[geom])
        start, n = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        z = pz + model.mesh_vert[start : start + n] @ rz
        return float(z.min()), float(z.max())
    else:  # planes, height fields, SDFs: scenery
        return float("inf"), float("-inf")
    return pz - float(e), pz + float(e)


def is_visual_only(model: mujoco.MjModel, gid: int) -> bool:
    """A mesh that does not collide (contype and conaffinity 0): drawn, not simulated.
    Robot models draw every link with such a mesh beside its collision geoms; the floor
    constraint and the floor figures leave them out (primitives are always kept)."""
    return (
        int(model.geom_type[gid]) == int(mujoco.mjtGeom.mjGEOM_MESH)
        and model.geom_contype[gid] == 0
        and model.geom_conaffinity[gid] == 0
    )


def character_geoms(model: mujoco.MjModel, collision_only: bool = False) -> list[int]:
    """Geoms attached to a moving body (not the world); optionally only colliding ones."""
    out = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == 0:
            continue
        if collision_only and model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        out.append(g)
    return out


def lowest_z(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int] | None = None) -> float:
    """Lowest world height of ``geoms`` (default: every character geom), metres."""
    geoms = character_geoms(model) if geoms is None else geoms
    return min((geom_z_extent(model, data, g)[0] for g in geoms), default=float("inf"))


def highest_z(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int] | None = None) -> float:
    """Highest world height of ``geoms`` (default: every character geom), metres."""
    geoms = character_geoms(model) if geoms is None else geoms
    return max((geom_z_extent(model, data, g)[1] for g in geoms), default=float("-inf"))
