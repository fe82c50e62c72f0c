"""Differential-IK retargeting with mink: targets, per-frame solver, hard limits, planting."""

from .retarget import retarget, solve_targets
from .solver import FrameSolver, SolverOptions
from .targets import TargetOptions, Targets, build_targets

__all__ = ["retarget", "solve_targets", "FrameSolver", "SolverOptions", "TargetOptions", "Targets", "build_targets"]
