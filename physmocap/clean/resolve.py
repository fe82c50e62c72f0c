r"""Re-solving a glitched span through the hard-limited IK on an actor-fitted humanoid.

The second repair of a rotational glitch (the first is the interpolation of
:mod:`.correct`), for the issue's "corrected poses respect the ranges of motion":

1. **Actor**: the default humanoid scaled to the source skeleton's own segment lengths
   (:func:`physmocap.models.scaling.scaled_humanoid_spec`, as the marker solve fits its
   actor), so its joint ranges are the goniometric ones of :mod:`physmocap.models.rom`.
2. **Targets** on the glitched joint :math:`j`'s span :math:`s..e` and its good neighbours
   :math:`a = s-1`, :math:`b = e+1`: every mapped joint centre where the glitch does not move
   it (the joints that are not below :math:`j`), and for the centres below :math:`j` their
   offset from :math:`j` in the frame of :math:`j`'s parent, turned at a steady rate from
   its value on frame :math:`a` to its value on frame :math:`b` (the neighbouring good
   frames' positions, interpolated) and carried by the parent's own motion.
3. **Solve**: each frame by the per-frame IK on the joint centres the marker solve poses its
   actor with (:func:`physmocap.markers.solve.pose_on_centres`: the joint ranges hard).
4. **Back to the file's channels**: the humanoid's own joint rotation
   :math:`W_P^{-1} W_B` (its body :math:`B` that joint :math:`j` moves, relative to the
   parent body :math:`P`), range-limited, becomes the file's local rotation
   :math:`C_p^{-1} (W_P^{-1} W_B)\,C_j`, where :math:`C_j = W_B^{-1} W_j` and
   :math:`C_p = W_P^{-1} W_p` are the offsets between the two skeletons' segment frames
   (:math:`W_j`, :math:`W_p`: the file's world rotations of joint :math:`j` and its
   parent), read on frames :math:`a` and :math:`b` and slerped between them, so the
   re-solved rotations join the good ones exactly at both ends.  (Taking the humanoid
   segment's world orientation instead would carry the hip's compensation into the knee:
   a knee target the humanoid cannot reach straight would still read hyperextended.)

By default (:func:`.correct.correct_glitches`, ``resolve="limits"``) a repair is re-solved
only where its interpolated pose leaves a range of motion (:func:`beyond_range_mask`) and the
re-solved pose does so on fewer of the span's frames: on the injected glitches of
``scripts/glitch_benchmark.py`` the interpolation stays within the ranges and rebuilds the
motion better on average (re-solving every repair of a frozen joint takes its error from
0.87 to 1.96 cm), but a cubic bridge between a knee straightening fast and bending fast
again overshoots into hyperextension (24 degrees past straight, 5 cm off), which the
limits stop (0.06 cm).

Only joints that map to a canonical joint the humanoid has (hips, knees, ankles, toes,
shoulders, elbows, wrists, spine, neck, head, clavicles) can be re-solved; the others keep
their interpolation.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..motion import Motion
from ..rotations import Rotation, quat_conj, quat_mul

__all__ = ["ActorIK", "actor_ik", "beyond_range_mask"]

#: Canonical joints the humanoid is posed on (the marker solve's calibration targets).
TARGETS = (
    "pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "left_toe", "right_toe", "spine", "chest", "neck", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand_end", "right_hand_end",
)  # fmt: skip


def _slerp_offsets(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(n, K, 3)``: each of ``K`` offsets turned from ``u (K, 3)`` to ``v (K, 3)`` at the
    fractions ``w (n,)``, direction at a steady rate, length linear (metres)."""
    from .correct import _slerp_vectors

    return np.stack([_slerp_vectors(u[k], v[k], w[:, None]) for k in range(len(u))], axis=1)


@dataclass
class ActorIK:
    """The actor-fitted humanoid and what re-solving a span on it needs (:func:`actor_ik`).

    Attributes:
        character: The scaled humanoid (:class:`~physmocap.models.Character`).
        names: Canonical joints posed on, in target order.
        source: ``(len(names),)`` their source joint indices.
        body_of: Source joint index -> humanoid body id it moves (the mapped joints).
        fps: The motion's frame rate.
    """

    character: Any
    names: list[str]
    source: np.ndarray
    body_of: dict[int, int]
    fps: float

    def can_resolve(self, j: int) -> bool:
        """Whether source joint ``j`` moves a humanoid body (it can be re-solved)."""
        return j in self.body_of

    def resolve(self, motion: Motion, R: np.ndarray, j: int, s: int, e: int) -> np.ndarray | None:
        """``(e - s + 1, 4)`` local rotations (x-y-z-w) of source joint ``j`` over frames
        ``s..e``, re-solved through the hard-limited IK (module docstring) with the motion's
        current rotations ``R (F, J, 4)`` everywhere else; None where it cannot be (the
        joint moves no humanoid body, or the span touches the clip's ends)."""
        import dataclasses

        from ..markers.solve import pose_on_centres

        F = len(R)
        a, b = s - 1, e + 1
        if j not in self.body_of or a < 0 or b >= F:
            return None
        frames = np.arange(a, b + 1)
        part = dataclasses.replace(motion, rotations=R).slice_frames(a, b + 1)
        P, W = part.forward_kinematics()
        C = _targets(np.asarray(P, float), np.asarray(W, float), self.source, motion.skeleton.parents, j)
        centres = {n: C[:, k] for k, n in enumerate(self.names)}
        Q = pose_on_centres(self.character, centres, self.names, C, np.arange(len(frames)), self.fps)
        model = self.character.model
        body = self.body_of[j]
        WB = _body_rotations(model, np.asarray(Q), body)
        WP = _body_rotations(model, np.asarray(Q), int(model.body_parentid[body]))
        return _back_to_local(WB, WP, np.asarray(W, float), motion.skeleton.parents, j)


def _targets(P: np.ndarray, W: np.ndarray, source: np.ndarray, parents: np.ndarray, j: int) -> np.ndarray:
    """``(n + 2, K, 3)`` joint-centre targets (metres) over a span and its two good ends
    (first and last rows) from the motion's positions ``P`` and world rotations ``W`` there:
    the joints below ``j`` get their offsets from ``j`` in its parent's frame interpolated
    (:func:`_slerp_offsets`) and carried by the parent; the others stay where they are."""
    from .detect import _descendants

    C = P[:, source].copy()
    below = np.flatnonzero(np.isin(source, _descendants(np.asarray(parents), j)))
    p = int(parents[j])
    if not len(below):
        return C
    Wp = Rotation.from_quat(W[:, p]).as_matrix() if p >= 0 else np.broadcast_to(np.eye(3), (len(P), 3, 3))
    off = np.einsum("fji,fkj->fki", Wp, P[:, source[below]] - P[:, j][:, None])  # in the parent's frame
    w = np.arange(len(P)) / (len(P) - 1)
    inner = _slerp_offsets(off[0], off[-1], w)
    C[:, below] = P[:, j][:, None] + np.einsum("fij,fkj->fki", Wp, inner)
    return C


def _body_rotations(model, Q: np.ndarray, body: int) -> np.ndarray:
    """``(n, 4)`` world rotations (x-y-z-w) of ``body`` at each ``qpos`` of ``Q (n, nq)``."""
    import mujoco

    data = mujoco.MjData(model)
    out = np.empty((len(Q), 4))
    for i, q in enumerate(Q):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        w, x, y, z = data.xquat[body]
        out[i] = (x, y, z, w)
    return out


def _end_offsets(WB: np.ndarray, WS: np.ndarray) -> np.ndarray:
    """``(n + 2, 4)``: the offset :math:`W_B^{-1} W_S` between a humanoid body's world rotations
    ``WB (n + 2, 4)`` and the file's segment's ``WS (n + 2, 4)``, read on the first and last
    frames (the good ends) and slerped between them."""
    from scipy.spatial.transform import Slerp

    ends = [0, len(WB) - 1]
    offset = Rotation.from_quat(quat_mul(quat_conj(WB[ends]), WS[ends]))
    return Slerp([0.0, 1.0], offset)(np.arange(len(WB)) / (len(WB) - 1)).as_quat()


def _back_to_local(WB: np.ndarray, WP: np.ndarray, W: np.ndarray, parents: np.ndarray, j: int) -> np.ndarray:
    r"""Joint ``j``'s local rotations on the span's inner frames from the humanoid's joint:
    its body's and its parent body's world rotations ``WB, WP (n + 2, 4)``, and the file's
    world rotations ``W (n + 2, J, 4)`` (good on the first and last frames).  The file's
    segments are the humanoid's turned by offsets read at the two ends and slerped over the
    span (:func:`_end_offsets`): :math:`W_j = W_B C_j`, :math:`W_p = W_P C_p`, so the local
    rotation :math:`W_p^{-1} W_j = C_p^{-1} (W_P^{-1} W_B) C_j` carries the humanoid's own,
    range-limited, joint rotation :math:`W_P^{-1} W_B` (module docstring, step 4)."""
    p = int(parents[j])
    Wp = W[:, p] if p >= 0 else np.broadcast_to([0.0, 0.0, 0.0, 1.0], WB.shape)
    Cj, Cp = _end_offsets(WB, W[:, j]), _end_offsets(WP, Wp)
    joint = quat_mul(quat_conj(WP), WB)
    return quat_mul(quat_mul(quat_conj(Cp), joint), Cj)[1:-1]


Segment = tuple[str, str]


def _segment_lengths(motion: Motion, ji: dict[str, int], base: dict[Segment, float]) -> dict[Segment, float]:
    """The source's segment lengths (metres, its first frame: a BVH's bones are rigid) for the
    humanoid segments it has both ends of."""
    from ..models.scaling import segment_lengths_from_positions

    P = np.asarray(motion.slice_frames(0, 1).world_positions(), float)[0]
    lengths = segment_lengths_from_positions({c: P[j] for c, j in ji.items()})
    return {seg: v for seg, v in lengths.items() if seg in base and v > 0.01}


def actor_ik(motion: Motion, ji: dict[str, int]) -> ActorIK | None:
    """The humanoid scaled to ``motion``'s skeleton (canonical joint -> source index ``ji``),
    or None when too few joints map to pose it (pelvis, both hips and the neck, which place
    its root)."""
    from ..markers.solve import load_spec_character
    from ..models.character import load_character
    from ..models.scaling import scaled_humanoid_spec

    if not all(c in ji for c in ("pelvis", "left_hip", "right_hip", "neck")):
        return None
    base = load_character()
    spec = scaled_humanoid_spec(_segment_lengths(motion, ji, base.segment_lengths))
    with tempfile.TemporaryDirectory(prefix="physmocap-clean-") as tmp:
        actor = load_spec_character(spec, Path(tmp), "actor")
    model = actor.model
    names = [c for c in TARGETS if c in ji and c in actor.tracked]
    body_of = {}
    for c, j in ji.items():  # a joint moves the body whose origin carries its site
        frame = actor.tracked.get(c)
        if frame is None or frame.kind != "site":
            continue
        sid = model.site(frame.name).id
        body = int(model.site_bodyid[sid])
        if np.allclose(model.site_pos[sid], 0.0) and model.body_jntnum[body] > 0:
            body_of[j] = body
    return ActorIK(actor, names, np.array([ji[c] for c in names]), body_of, float(motion.fps))


def beyond_range_mask(motion: Motion, opt, ji: dict[str, int]) -> np.ndarray:
    """``(F, J)`` bool: the frames where an anatomical movement (:mod:`.anatomy`) that source
    joint ``j`` can change is beyond its range of motion (``opt.rom_soft_margin`` included,
    as the detector reads it: :func:`.detect.anatomical_glitches`)."""
    from .anatomy import MOVEMENTS, beyond_range, motion_angles, movement_range
    from .detect import _movement_joints

    mask = np.zeros((motion.num_frames, len(motion.skeleton.names)), dtype=bool)
    if not ji:
        return mask
    angles, _ = motion_angles(motion, ji)
    for m in MOVEMENTS:
        if m.key not in angles:
            continue
        joints = sorted(_movement_joints(motion, ji, m))
        for start, end, _, _ in beyond_range(angles[m.key], *movement_range(m, opt.rom_soft_margin)):
            mask[start : end + 1, joints] = True
    return mask
