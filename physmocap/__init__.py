"""physmocap: solved motion capture to clean, physically valid character motion.

Pipeline: a source (``physmocap.sources``) reads a file into a
:class:`~physmocap.motion.Motion`; the retargeter (``physmocap.ik``) drives a
character (``physmocap.models``) with mink differential IK; exporters
(``physmocap.export``) write the character's trajectory.
"""

from __future__ import annotations

from .render.backend import select_backend_env

select_backend_env()  # MuJoCo reads MUJOCO_GL when it is first imported: choose before that

from .errors import InputError, MappingError, OptionError, OutputError, PhysmocapError

__version__ = "0.1.0"

#: Names imported on first use (numpy/scipy load only when needed: ``physmocap --help`` is fast).
_LAZY = {"Motion": "motion", "Skeleton": "motion", "forward_kinematics": "motion", "RetargetConfig": "ik.config"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'physmocap' has no attribute {name!r}")


def retarget(motion, character=None, config=None, **options):
    """Retarget a :class:`Motion` onto a character; see :func:`physmocap.ik.retarget.retarget`."""
    from .ik.retarget import retarget as _retarget

    return _retarget(motion, character, config, **options)


def load_motion(path, **options):
    """Read a capture file (or ``"example"``); see :func:`physmocap.sources.load_motion`."""
    from .sources import load_motion as _load

    return _load(path, **options)


def load_character(path=None, map_path=None, **options):
    """Load a character; see :func:`physmocap.models.load_character`."""
    from .models import load_character as _load

    return _load(path, map_path, **options)

__all__ = [
    "Motion",
    "Skeleton",
    "forward_kinematics",
    "retarget",
    "RetargetConfig",
    "load_motion",
    "load_character",
    "PhysmocapError",
    "InputError",
    "MappingError",
    "OptionError",
    "OutputError",
    "__version__",
]
