"""physmocap: solved motion capture to clean, physically valid character motion.

Pipeline: a source (``physmocap.sources``) reads a file into a
:class:`~physmocap.motion.Motion`; the retargeter (``physmocap.ik``) drives a
character (``physmocap.models``) with mink differential IK; exporters
(``physmocap.export``) write the character's trajectory.
"""

from __future__ import annotations

from .errors import InputError, MappingError, OptionError, OutputError, PhysmocapError
from .motion import Motion, Skeleton, forward_kinematics

__version__ = "0.1.0"

__all__ = [
    "Motion",
    "Skeleton",
    "forward_kinematics",
    "PhysmocapError",
    "InputError",
    "MappingError",
    "OptionError",
    "OutputError",
    "__version__",
]
