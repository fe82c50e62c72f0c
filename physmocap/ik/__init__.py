"""Differential-IK retargeting with mink: configuration, targets, the per-frame pipeline, planting."""

from .config import RetargetConfig
from .frame import FrameResult, FrameRetargeter
from .retarget import retarget, solve_targets
from .solver import FrameSolver, SolverOptions
from .targets import TargetOptions, Targets, build_targets

__all__ = [
    "RetargetConfig",
    "retarget",
    "solve_targets",
    "FrameRetargeter",
    "FrameResult",
    "FrameSolver",
    "SolverOptions",
    "TargetOptions",
    "Targets",
    "build_targets",
]
