"""Which of a character's collision geoms must not pass through each other (self-collision).

A character's limbs are found from its mapping, not from names: the **limb** of a
canonical joint (``left_knee``, ``right_elbow``...) is the subtree of the body,
among the trunk's children, that carries it (for a leg the child of the body
that holds the pelvis frame; for an arm the body nearest the trunk on the way
from the elbow).  Every collision geom of the character belongs to one group:
``left_leg``, ``right_leg``, ``left_arm``, ``right_arm`` or ``trunk`` (the rest:
pelvis, spine, chest, neck, head); a leg's toe segment (the subtree of the body
carrying the toe joint, when it is not the foot's) belongs to none.  The pairs
checked (:data:`GROUP_PAIRS`) are
the legs against each other, the arms against each other, and each arm against
the trunk and both legs; the legs against the trunk are left out (the hips are
where they meet).  A geom pair is dropped when its bodies are the same, parent
and child, or when the two geoms already touch or overlap in the rest pose (a
shoulder link inside the torso is the model's own construction, not a
collision).  Units: metres.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .geometry import character_geoms

__all__ = ["GROUP_PAIRS", "limb_groups", "self_collision_pairs", "pair_distances"]

#: Groups whose geoms must keep apart.
GROUP_PAIRS: tuple[tuple[str, str], ...] = (
    ("left_leg", "right_leg"),
    ("left_arm", "right_arm"),
    ("left_arm", "trunk"),
    ("right_arm", "trunk"),
    ("left_arm", "left_leg"),
    ("left_arm", "right_leg"),
    ("right_arm", "left_leg"),
    ("right_arm", "right_leg"),
)
#: Limb group -> the canonical joints that identify it (the first one mapped is used).
_LIMB_JOINTS = {
    "left_leg": ("left_knee", "left_ankle"),
    "right_leg": ("right_knee", "right_ankle"),
    "left_arm": ("left_elbow", "left_wrist"),
    "right_arm": ("right_elbow", "right_wrist"),
}


def _body_of(character, canonical: str) -> int | None:
    tf = character.tracked.get(canonical)
    if tf is None:
        return None
    return tf.body_id(character.model)


def _chain(model: mujoco.MjModel, body: int) -> list[int]:
    """``body`` and its ancestors up to (not including) the world, nearest first."""
    out = []
    while body > 0:
        out.append(body)
        body = int(model.body_parentid[body])
    return out


def _subtree(model: mujoco.MjModel, root: int) -> set[int]:
    out = {root}
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in out:
            out.add(b)
    return out


def limb_groups(character) -> dict[str, set[int]]:
    """Group name -> body ids (see the module docstring); limbs that cannot be found are
    left out, their bodies counted as trunk; toe segments are in no group."""
    model = character.model
    pelvis = _body_of(character, "pelvis")
    trunk_chain = set(_chain(model, pelvis)) if pelvis is not None else set()
    # the trunk's spine: bodies from the pelvis up to the chest / neck / head
    for canon in ("spine", "chest", "neck", "head"):
        b = _body_of(character, canon)
        if b is not None:
            trunk_chain |= set(_chain(model, b))
    groups: dict[str, set[int]] = {}
    for group, joints in _LIMB_JOINTS.items():
        b = next((x for x in (_body_of(character, j) for j in joints) if x is not None), None)
        if b is None:
            continue
        chain = _chain(model, b)
        # the limb's root: the last body on the way up before the trunk
        root = None
        for x in chain:
            if x in trunk_chain:
                break
            root = x
        if root is not None:
            groups[group] = _subtree(model, root)
    # toe segments are left out: a flicked toe is the cheapest way around a brushing foot,
    # and toes passing each other are no visible fault
    toes = set()
    for side in ("left", "right"):
        toe, ankle = _body_of(character, f"{side}_toe"), _body_of(character, f"{side}_ankle")
        if toe is not None and toe != ankle and f"{side}_leg" in groups and toe in groups[f"{side}_leg"]:
            toes |= _subtree(model, toe)
            groups[f"{side}_leg"] -= toes
    limbs = set().union(*groups.values()) if groups else set()
    limbs |= toes
    groups["trunk"] = {b for b in range(1, model.nbody) if b not in limbs}
    return groups


def _adjacent(model: mujoco.MjModel, b1: int, b2: int) -> bool:
    w1, w2 = int(model.body_weldid[b1]), int(model.body_weldid[b2])
    if w1 == w2:
        return True
    p1, p2 = int(model.body_weldid[model.body_parentid[w1]]), int(model.body_weldid[model.body_parentid[w2]])
    return p1 == w2 or p2 == w1


def self_collision_pairs(character, rest_clearance: float = 0.01) -> list[tuple[int, int]]:
    """Sorted geom-id pairs ``(g1 < g2)`` that must not interpenetrate.

    Args:
        character: A :class:`~physmocap.models.Character`.
        rest_clearance: A pair closer than this in the rest pose (metres) is dropped.
    """
    model = character.model
    groups = limb_groups(character)
    geoms = character_geoms(model, collision_only=True)
    of_group = {name: [g for g in geoms if int(model.geom_bodyid[g]) in bodies] for name, bodies in groups.items()}
    data = character.rest_data()
    fromto = np.empty(6)
    pairs = set()
    for a, b in GROUP_PAIRS:
        for g1 in of_group.get(a, ()):
            for g2 in of_group.get(b, ()):
                b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
                if g1 == g2 or _adjacent(model, b1, b2):
                    continue
                if mujoco.mj_geomDistance(model, data, g1, g2, rest_clearance + 0.05, fromto) <= rest_clearance:
                    continue
                pairs.add((min(g1, g2), max(g1, g2)))
    return sorted(pairs)


def pair_distances(model: mujoco.MjModel, data: mujoco.MjData, pairs: list[tuple[int, int]], cutoff: float = 0.05) -> np.ndarray:
    """``(len(pairs),)`` signed distances (metres; negative: penetration) of ``pairs`` in
    ``data``'s pose, capped at ``cutoff``."""
    fromto = np.empty(6)
    return np.array([mujoco.mj_geomDistance(model, data, g1, g2, cutoff, fromto) for g1, g2 in pairs])
