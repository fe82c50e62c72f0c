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

import hashlib

import mujoco
import numpy as np

__all__ = ["geom_z_extent", "geom_candidates", "hull_vertices", "character_geoms", "is_visual_only", "lowest_z", "highest_z"]


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


def hull_vertices(model: mujoco.MjModel, mesh: int) -> np.ndarray:
    """The vertices of a mesh's convex hull (its lowest point is always one of them):
    a robot's foot mesh of 10,000 vertices has a few hundred.  A new array; hulls are
    kept per vertex set for the process (a robot's meshes, a batch's next clip)."""
    start, n = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    v = np.asarray(model.mesh_vert[start : start + n], dtype=float)
    if n < 16:
        return v
    key = hashlib.blake2b(v.tobytes(), digest_size=20).digest()
    hull = _HULLS.get(key)
    if hull is None:
        try:
            from scipy.spatial import ConvexHull

            hull = v[np.sort(ConvexHull(v).vertices)]
        except Exception:  # noqa: BLE001 - flat or degenerate meshes: keep every vertex
            hull = v
        if len(_HULLS) >= _MAX_HULLS:
            _HULLS.pop(next(iter(_HULLS)))
        _HULLS[key] = hull
    return hull.copy()


#: Convex hulls already computed: digest of a mesh's vertices -> its hull vertices (the oldest
#: dropped beyond :data:`_MAX_HULLS`).
_HULLS: dict[bytes, np.ndarray] = {}
_MAX_HULLS = 256


def geom_candidates(model: mujoco.MjModel, gid: int) -> np.ndarray:
    """Points in the geom's frame whose lowest one, less a radius, is the geom's lowest point.

    Returns ``(k, 4)`` rows ``(x, y, z, radius)``: spheres and capsules are
    handled exactly (centre / end-cap centres with their radius), boxes by their
    eight corners, cylinders and ellipsoids conservatively by the corners of
    their bounding box, meshes by their vertices.
    """
    t = int(model.geom_type[gid])
    s = model.geom_size[gid]
    G = mujoco.mjtGeom
    if t == int(G.mjGEOM_SPHERE):
        return np.array([[0.0, 0.0, 0.0, s[0]]])
    if t == int(G.mjGEOM_CAPSULE):
        return np.array([[0.0, 0.0, s[1], s[0]], [0.0, 0.0, -s[1], s[0]]])
    if t in (int(G.mjGEOM_BOX), int(G.mjGEOM_ELLIPSOID), int(G.mjGEOM_CYLINDER)):
        hx, hy, hz = (s[0], s[1], s[2]) if t != int(G.mjGEOM_CYLINDER) else (s[0], s[0], s[1])
        corners = np.array([[sx * hx, sy * hy, sz * hz, 0.0] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return corners
    if t == int(G.mjGEOM_MESH):
        v = hull_vertices(model, int(model.geom_dataid[gid]))
        return np.hstack([v, np.zeros((len(v), 1))])
    # planes, heightfields, SDFs: not constrained
    return np.zeros((0, 4))


def subtree_bodies(model: mujoco.MjModel, roots: set[int]) -> list[int]:
    """The bodies at or below any of ``roots`` (body ids), in id order: a foot's bodies
    are those of its contact sites and every body below them (toes)."""
    out = []
    for b in range(1, model.nbody):
        a = b
        while a > 0 and a not in roots:
            a = int(model.body_parentid[a])
        if a > 0:
            out.append(b)
    return out


def foot_bodies(model: mujoco.MjModel, contacts: dict[str, tuple[str, ...]]) -> dict[str, list[int]]:
    """Side -> the bodies of that foot (:func:`subtree_bodies` of its contact sites' bodies)."""
    return {
        side: subtree_bodies(model, {int(model.site(s).bodyid[0]) for s in sites})
        for side, sites in contacts.items()
        if sites
    }
