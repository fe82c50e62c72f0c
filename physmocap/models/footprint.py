"""Foot contact points found from a model's geometry, for a mapping without ``[contacts]``.

For each foot, the bodies from the mapped ankle's body down (toes included) carry collision
geoms (visual-only meshes and non-colliding geoms are left out; if a foot has none, every
geom of those bodies is used).  In the rest pose, standing with +X forward, their lowest
surface points (:func:`~physmocap.models.geometry.geom_candidates`: capsule and sphere ends
less their radius, box corners, mesh hull vertices) within ``tolerance`` of the lowest are
the sole; the middle of its rear edge is the heel and of its front edge the toe.  They become sites on
the ankle's body (``left_auto_heel``, ``left_auto_toe``...).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .geometry import geom_candidates, is_visual_only

__all__ = ["foot_contact_points"]


def _subtree(model: mujoco.MjModel, root: int) -> list[int]:
    out = []
    for b in range(model.nbody):
        a = b
        while a > 0 and a != root:
            a = int(model.body_parentid[a])
        if a == root:
            out.append(b)
    return out


def foot_contact_points(
    model: mujoco.MjModel, qpos: np.ndarray, ankle_bodies: dict[str, int], tolerance: float = 0.005
) -> dict[str, list[tuple[str, int, np.ndarray]]]:
    """Side -> ``[(site name, body id, position in that body's frame), heel then toe]``."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    out: dict[str, list[tuple[str, int, np.ndarray]]] = {}
    for side, body in ankle_bodies.items():
        bodies = set(_subtree(model, body))
        geoms = [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in bodies]
        colliding = [g for g in geoms if not is_visual_only(model, g) and (model.geom_contype[g] or model.geom_conaffinity[g])]
        points = []
        for g in colliding or geoms:
            cand = geom_candidates(model, g)
            if not len(cand):
                continue
            R = data.geom_xmat[g].reshape(3, 3)
            p = data.geom_xpos[g] + cand[:, :3] @ R.T
            p[:, 2] -= np.maximum(cand[:, 3], 0.0)
            points.append(p)
        if not points:
            continue
        P = np.concatenate(points)
        sole = P[P[:, 2] <= P[:, 2].min() + tolerance]
        # the middle of the sole's rear and front edges (points within 1 cm of the extremes)
        heel = sole[sole[:, 0] <= sole[:, 0].min() + 0.01].mean(axis=0)
        toe = sole[sole[:, 0] >= sole[:, 0].max() - 0.01].mean(axis=0)
        Rb, xb = data.xmat[body].reshape(3, 3), data.xpos[body]
        out[side] = [(f"{side}_auto_{name}", body, Rb.T @ (pt - xb)) for name, pt in (("heel", heel), ("toe", toe))]
    return out
