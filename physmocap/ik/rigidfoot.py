r"""A character whose foot is one rigid body follows the actor's ankle-to-toe-tip line.

The actor's foot bends at the toes; a robot's foot (or any character without a toe
joint between its ankle and its toe site) does not.  When the actor rolls onto the
toes (heel up, toe tips on the floor), the actor's foot segment (ankle to ball) pitches
down much further than a rigid foot can while its front edge stays on the floor: the
rigid foot's attitude is that of the line from the ankle to the toe tips.  Tracking the
foot segment's rotation there makes the character's foot fight its toe hold all through
the roll and snap to the foot segment's attitude (at its velocity cap) when the toes
lift.

So a rigid foot's orientation target is the actor's foot rotation :math:`R_a(t)`
corrected by the smallest rotation that takes the toe-tip direction the foot would
have with its toes as in the calibration pose onto the actor's actual one:

.. math::

    C(t) = \operatorname{between}\!\big(R_a(t)\, u,\ \widehat{x_{tip}(t) - x_{ankle}(t)}\big),
    \qquad u = R_a(c)^{-1}\, \widehat{x_{tip}(c) - x_{ankle}(c)},

where :math:`c` is the calibration pose (the pose the orientation targets are
calibrated on, so :math:`C(c) = I`).  With straight toes :math:`C` is the identity; a
toe flexion of :math:`\theta` turns the target by about :math:`\theta` times the share
of the tip line the toes make.  The target of the foot's front site (the ball) turns
with it.  Directions are unit vectors in the levelled world (metres, x-y-z-w).
"""

from __future__ import annotations

import numpy as np

from ..rotations import quat_apply, quat_between, quat_conj

__all__ = ["tip_reference", "toe_line_correction"]


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12), n[..., 0]


def tip_reference(rotation: np.ndarray, ankle: np.ndarray, tip: np.ndarray) -> np.ndarray | None:
    """The actor's toe-tip direction ``u (3,)`` in the frame of its foot, from one pose
    (``rotation (4,)``: the foot's world rotation; ``ankle``, ``tip (3,)``: positions), or
    None where the tip coincides with the ankle."""
    d, n = _unit(np.asarray(tip, dtype=float) - np.asarray(ankle, dtype=float))
    if not np.isfinite(n) or n < 1e-6:
        return None
    return quat_apply(quat_conj(np.asarray(rotation, dtype=float)), d)


def toe_line_correction(rotations: np.ndarray, ankle: np.ndarray, tip: np.ndarray, u: np.ndarray,
                        valid: np.ndarray) -> np.ndarray:
    """``C (F, 4)``: per frame, the smallest rotation taking the foot's rigid toe-tip
    direction ``R_a(t) u`` onto the actor's ankle-to-tip direction; the identity where
    ``valid (F,)`` is False or the tip sits on the ankle.

    Args:
        rotations: ``(F, 4)`` the actor's foot world rotations.
        ankle, tip: ``(F, 3)`` the actor's ankle and toe-tip positions.
        u: ``(3,)`` from :func:`tip_reference`.
        valid: ``(F,)`` frames where both positions are known.
    """
    actual, n = _unit(tip - ankle)
    rigid = quat_apply(rotations, np.broadcast_to(u, actual.shape))
    C = quat_between(rigid, actual)
    bad = ~valid | (n < 1e-6) | ~np.all(np.isfinite(C), axis=-1)
    C[bad] = (0.0, 0.0, 0.0, 1.0)
    return C
