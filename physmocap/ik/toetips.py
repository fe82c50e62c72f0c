r"""Toe tips for skeletons whose toe end sites have no length.

Some vendors write the end site below the toe joint at the joint itself (zero
offset: Bandai Namco's dataset-1, LAFAN1-style exports), so the actor's toe
segment has no direction and a character's toe tip gets no target: its toes
cannot roll with the actor's and stay wherever the IK leaves them.

For a rotational source the toe joint's rotation is known, so the tip can be
given back: the end site is placed on the continuation of the foot bone in the
toe joint's own frame, :math:`o_{tip} = \ell\, \hat o_{toe}` with
:math:`\hat o_{toe}` the direction of the toe joint's offset from the ankle
(BVH frames are world-aligned at rest, so that is also its direction in the
toe's frame) and :math:`\ell` the actor's foot length times the character's
toe-to-foot length ratio.  Where the actor's toes are flat the feet are
levelled anyway (:mod:`physmocap.ik.footlevel`), so only the toe joint's
rotation relative to that matters, which is the actor's own.  Offline
retargeting (:func:`~physmocap.ik.retarget.retarget`) applies it after mapping
the skeleton; the streaming retargeter does not yet (its feet are not levelled
either).  Units: metres.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..motion import Motion

__all__ = ["extend_toe_tips"]


def extend_toe_tips(motion: Motion, joint_indices: dict[str, int], rest: dict[str, np.ndarray]) -> tuple[Motion, dict[str, int]]:
    """``(motion, joint_indices)`` with zero-length toe end sites given a length and mapped as
    ``<side>_toe_end`` (see the module docstring); unchanged where nothing applies.

    Args:
        motion: The actor's motion (not modified; a copy with a new skeleton is returned).
        joint_indices: Canonical joint -> source joint index.
        rest: The character's rest positions by canonical joint
            (:meth:`~physmocap.models.Character.rest_positions`).
    """
    if not motion.is_rotational:
        return motion, joint_indices
    sk = motion.skeleton
    offsets = sk.offsets.copy()
    out = dict(joint_indices)
    for side in ("left", "right"):
        ankle, toe, tip = f"{side}_ankle", f"{side}_toe", f"{side}_toe_end"
        if tip in out or toe not in out or ankle not in out or not all(j in rest for j in (ankle, toe, tip)):
            continue
        t = out[toe]
        ends = [j for j in np.flatnonzero(sk.parents == t) if sk.end_site[j] and np.linalg.norm(sk.offsets[j]) < 1e-6]
        foot = np.linalg.norm(sk.offsets[t])
        char_foot = np.linalg.norm(rest[toe] - rest[ankle])
        if not ends or foot < 1e-6 or char_foot < 1e-9:
            continue
        ratio = float(np.linalg.norm(rest[tip] - rest[toe]) / char_foot)
        offsets[ends[0]] = sk.offsets[t] * ratio
        out[tip] = int(ends[0])
    if out == joint_indices:
        return motion, joint_indices
    skeleton = dataclasses.replace(sk, offsets=offsets)
    return dataclasses.replace(motion, skeleton=skeleton), out
