"""The preview camera: a view direction and a look-at point that follows the pelvis.

Views are relative to the character's facing on the first frame (so ``side``
shows a walk from the side whichever way the actor walked): ``side`` looks at
the character's right side, ``front`` at its face, ``back`` from behind,
``top`` from above.  ``AZ,EL`` gives MuJoCo's world azimuth and elevation in
degrees instead (azimuth 0 looks along +X, elevation < 0 looks down).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..errors import OptionError

__all__ = ["CameraSpec", "beside_offset", "follow", "heading_degrees"]

#: view -> (azimuth relative to the facing, elevation), degrees.
VIEWS = {"side": (90.0, -12.0), "front": (180.0, -12.0), "back": (0.0, -12.0), "top": (90.0, -89.0)}


@dataclass(frozen=True)
class CameraSpec:
    """``view`` (a :data:`VIEWS` key) or absolute ``azimuth``/``elevation`` in degrees."""

    view: str | None = "side"
    azimuth: float = 0.0
    elevation: float = 0.0

    def __post_init__(self) -> None:
        if self.view is not None and self.view not in VIEWS:
            raise OptionError(f"unknown camera view {self.view!r}; use one of {sorted(VIEWS)} or AZIMUTH,ELEVATION")
        if not (math.isfinite(self.azimuth) and -90.0 <= self.elevation <= 90.0):
            raise OptionError(f"camera elevation must be within [-90, 90] degrees, got {self.elevation}")

    @classmethod
    def parse(cls, text: str) -> "CameraSpec":
        """``side``, ``front``, ``back``, ``top`` or ``AZ,EL`` (degrees)."""
        text = text.strip().lower()
        if "," not in text:
            return cls(view=text)
        try:
            az, el = (float(v) for v in text.split(","))
        except ValueError:
            raise OptionError(f"--camera {text!r}: expected a view name or AZIMUTH,ELEVATION in degrees") from None
        return cls(view=None, azimuth=az, elevation=el)

    def angles(self, heading: float) -> tuple[float, float]:
        """(azimuth, elevation) in degrees for a character facing ``heading`` degrees."""
        if self.view is None:
            return self.azimuth, self.elevation
        az, el = VIEWS[self.view]
        return heading + az, el


def heading_degrees(character, qpos: np.ndarray) -> float:
    """World heading (degrees about +Z) the character faces in pose ``qpos``.

    Facing is :math:`(l - r) \\times \\hat z` from the left and right hip joints
    (robust to a bent torso), else the root body's rotation of the rest
    forward axis (+X).
    """
    model = character.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    if "left_hip" in character.tracked and "right_hip" in character.tracked:
        def where(canon: str) -> np.ndarray:
            i = character.frame_id(canon)
            return data.site_xpos[i] if character.tracked[canon].kind == "site" else data.xpos[i]

        forward = np.cross(where("left_hip") - where("right_hip"), [0.0, 0.0, 1.0])
    else:
        root = int(model.jnt_bodyid[model.joint(character.root_joint).id])
        now = data.xmat[root].reshape(3, 3).copy()
        data.qpos[:] = character.rest_qpos
        mujoco.mj_kinematics(model, data)
        forward = now @ data.xmat[root].reshape(3, 3).T @ np.array([1.0, 0.0, 0.0])
    return math.degrees(math.atan2(forward[1], forward[0]))


def beside_offset(azimuth: float, size: float) -> np.ndarray:
    """Where the source skeleton goes beside the character: ``0.8 size`` metres to the
    right of a camera at ``azimuth`` degrees (horizontal)."""
    a = math.radians(azimuth)
    return np.array([math.sin(a), -math.cos(a), 0.0]) * 0.8 * size


def follow(points: np.ndarray, fps: float, window: float = 0.5) -> np.ndarray:
    """``(F, 3)`` positions smoothed by a centred moving average over ``window`` seconds
    (edges padded with the end values), so the camera follows without jitter."""
    pts = np.asarray(points, dtype=float)
    k = max(int(round(window * fps)) | 1, 1)
    if k == 1 or pts.shape[0] < 2:
        return pts.copy()
    pad = np.concatenate([np.repeat(pts[:1], k // 2, 0), pts, np.repeat(pts[-1:], k // 2, 0)])
    c = np.cumsum(np.concatenate([np.zeros((1, 3)), pad]), axis=0)
    return (c[k:] - c[:-k]) / k
