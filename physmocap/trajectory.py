"""The character's joint trajectory: what the retargeter produces and exporters write.

``qpos`` is MuJoCo's generalised position per frame (``(F, nq)``, MuJoCo
order): for the free root joint the world position in metres then the
orientation as a **w-x-y-z** quaternion (MuJoCo's convention), then one value
per hinge (radians) or slide (metres) joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from .rotations import wxyz_to_xyzw

__all__ = ["Trajectory", "SolverStats", "qpos_column_names"]


def qpos_column_names(model: mujoco.MjModel) -> list[str]:
    """One name per qpos column: ``<joint>_x/_y/_z/_qw/_qx/_qy/_qz`` for free joints,
    ``<joint>_qw..`` for ball joints, the joint name for hinges and slides."""
    names: list[str] = []
    for j in range(model.njnt):
        name = model.joint(j).name or f"joint{j}"
        t = int(model.jnt_type[j])
        if t == mujoco.mjtJoint.mjJNT_FREE:
            names += [f"{name}_{s}" for s in ("x", "y", "z", "qw", "qx", "qy", "qz")]
        elif t == mujoco.mjtJoint.mjJNT_BALL:
            names += [f"{name}_{s}" for s in ("qw", "qx", "qy", "qz")]
        else:
            names.append(name)
    return names


@dataclass(frozen=True)
class SolverStats:
    """Per-frame figures of the IK that produced a trajectory.

    Attributes:
        iterations: ``(F,)`` QP iterations of each frame.
        relaxation: ``(F,)`` strongest relaxation a frame needed, an index into
            :data:`physmocap.ik.solver.RELAXATION_LEVELS` (0: every constraint held).
        latency: ``(F,)`` wall time of each frame (seconds).
    """

    iterations: np.ndarray
    relaxation: np.ndarray
    latency: np.ndarray


@dataclass(eq=False)
class Trajectory:
    """A character's motion as joint positions over frames.

    What the retargeter knew is kept with it, typed: the targets it tracked,
    the contacts it planted, the source motion as retargeted (cut and
    resampled), the source's canonical joints, the first source frame used,
    the solver's per-frame figures and the fidelity figures.  Each is None
    (``source_start`` 0) for a trajectory read from a file or built by hand.

    Attributes:
        character: The :class:`physmocap.models.Character` it drives.
        qpos: ``(F, nq)`` MuJoCo generalised positions (quaternions w-x-y-z).
        fps: Frames per second.
        source: Where the input motion came from.
        targets: The IK targets (:class:`physmocap.ik.targets.Targets`).
        contacts: The contact labels used (:class:`physmocap.ik.contacts.Contacts`).
        source_motion: The source :class:`~physmocap.motion.Motion` as retargeted.
        joint_indices: Canonical joint -> joint index in ``source_motion``.
        source_start: Frame of the source file that frame 0 comes from.
        solver: Per-frame :class:`SolverStats`.
        fidelity: :class:`physmocap.metrics.fidelity.Fidelity` figures.
    """

    character: object
    qpos: np.ndarray
    fps: float
    source: str = "<memory>"
    targets: object | None = None
    contacts: object | None = None
    source_motion: object | None = None
    joint_indices: dict[str, int] | None = None
    source_start: int = 0
    solver: SolverStats | None = None
    fidelity: object | None = None

    @property
    def model(self) -> mujoco.MjModel:
        return self.character.model  # type: ignore[attr-defined]

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def column_names(self) -> list[str]:
        return qpos_column_names(self.model)

    def _run(self, fn) -> np.ndarray:
        """``fn(data)`` after the kinematics of every frame, stacked ``(F, ...)`` into one
        array allocated once (not a list of per-frame arrays)."""
        model = self.model
        data = mujoco.MjData(model)
        out: np.ndarray | None = None
        for t, q in enumerate(self.qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            value = np.asarray(fn(data))
            if out is None:
                out = np.empty((self.num_frames, *value.shape), dtype=value.dtype)
            out[t] = value
        return np.empty((0,)) if out is None else out

    def body_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """World ``(positions (F, nbody, 3), quaternions (F, nbody, 4) x-y-z-w)``."""
        model = self.model
        data = mujoco.MjData(model)
        pos = np.empty((self.num_frames, model.nbody, 3))
        quat = np.empty((self.num_frames, model.nbody, 4))
        for t, q in enumerate(self.qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            pos[t] = data.xpos
            quat[t] = wxyz_to_xyzw(data.xquat)
        return pos, quat

    def site_positions(self, sites: list[str]) -> np.ndarray:
        """``(F, len(sites), 3)`` world positions of named sites."""
        ids = [self.model.site(s).id for s in sites]
        return self._run(lambda d: d.site_xpos[ids].copy())
