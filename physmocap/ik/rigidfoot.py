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

from ..rotations import quat_apply, quat_between, quat_conj, quat_mul
from ..vectors import unit

__all__ = ["tip_reference", "toe_line_correction", "level_roll"]


def tip_reference(rotation: np.ndarray, ankle: np.ndarray, tip: np.ndarray) -> np.ndarray | None:
    """The actor's toe-tip direction ``u (3,)`` in the frame of its foot, from one pose
    (``rotation (4,)``: the foot's world rotation; ``ankle``, ``tip (3,)``: positions), or
    None where the tip coincides with the ankle."""
    d, n = unit(np.asarray(tip, dtype=float) - np.asarray(ankle, dtype=float), 1e-12)
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
    actual, n = unit(tip - ankle, 1e-12)
    rigid = quat_apply(rotations, np.broadcast_to(u, actual.shape))
    C = quat_between(rigid, actual)
    bad = ~valid | (n < 1e-6) | ~np.all(np.isfinite(C), axis=-1)
    C[bad] = (0.0, 0.0, 0.0, 1.0)
    return C


#: Pitch (radians) of a foot's forward axis up to which :func:`level_roll` levels it fully,
#: and beyond which not at all: a foot standing on its tip has its edge level whatever its
#: roll, and levelling it there would turn it about its (nearly vertical) long axis.
LEVEL_PITCH_FULL = np.radians(45.0)
LEVEL_PITCH_NONE = np.radians(75.0)


def level_roll(orientations: np.ndarray, rest_quat: np.ndarray, weights: np.ndarray, block: int = 65536) -> np.ndarray:
    r"""``(F, 4)`` ankle orientation targets turned about the foot's forward axis until its
    lateral axis is horizontal, by ``weights (F,)`` (0: unchanged, 1: level).

    A rigid foot rolling over its front edge keeps that edge on the floor only while its
    lateral axis stays level; the actor's foot at toe-off turns about its long axis too
    (10-30 degrees on the PyMO walk), which the toes absorb, and a rigid foot following it
    tips onto one corner of its edge, the corner sliding as the roll grows (the bundled
    robot's foot slip on the PyMO walk).  With :math:`R = Q\,Q_0^{-1}` the rotation from
    the rest pose (facing +X, Z up), :math:`f = R\hat x`, :math:`l = R\hat y`, turning
    :math:`l` by :math:`\varphi` about :math:`f` gives :math:`l\cos\varphi + (f \times l)
    \sin\varphi`, level for :math:`\varphi = \arctan(-l_z / (f \times l)_z)` (the
    smaller of the two turns).  The turn is :math:`w\,s\,\varphi`, with :math:`s` fading
    from 1 to 0 as the foot pitches from :data:`LEVEL_PITCH_FULL` to :data:`LEVEL_PITCH_NONE`.

    Args:
        orientations: ``(F, 4)`` x-y-z-w ankle orientation targets.
        rest_quat: ``(4,)`` the ankle frame's rest orientation.
        weights: ``(F,)`` in [0, 1].
        block: Frames computed at a time (a long clip's temporaries stay bounded).
    """
    q = np.asarray(orientations, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)  # the formulas below need unit quaternions
    w = np.asarray(weights, dtype=float)
    out = np.empty_like(q)
    for s in range(0, len(q), block):
        out[s : s + block] = _level_roll(q[s : s + block], np.asarray(rest_quat, dtype=float), w[s : s + block])
    return out


def _level_roll(q: np.ndarray, rest_quat: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """:func:`level_roll` of one block of frames."""
    R = quat_mul(q, quat_conj(rest_quat))
    f = quat_apply(R, np.broadcast_to([1.0, 0.0, 0.0], q[:, :3].shape))
    lat = quat_apply(R, np.broadcast_to([0.0, 1.0, 0.0], q[:, :3].shape))
    up = np.cross(f, lat)[:, 2]
    phi = np.arctan2(-lat[:, 2], up)
    phi = np.where(np.abs(phi) > np.pi / 2.0, phi - np.sign(phi) * np.pi, phi)  # the smaller turn
    pitch = np.arcsin(np.clip(np.abs(f[:, 2]), 0.0, 1.0))
    x = np.clip((LEVEL_PITCH_NONE - pitch) / (LEVEL_PITCH_NONE - LEVEL_PITCH_FULL), 0.0, 1.0)
    half = 0.5 * weights * x * x * (3.0 - 2.0 * x) * phi
    C = np.concatenate([f * np.sin(half)[:, None], np.cos(half)[:, None]], axis=1)
    return quat_mul(C, q)
