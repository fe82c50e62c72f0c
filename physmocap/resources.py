"""Locate the files that ship with physmocap: character models and the example clip."""

from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent

#: Name accepted wherever a motion file is expected, meaning the bundled clip.
EXAMPLE_NAME = "example"


def example_clip() -> Path:
    """The bundled example clip: CMU subject 12, trial 01, a steady walk (120 Hz BVH).

    Data from mocap.cs.cmu.edu, created with funding from NSF EIA-0196217.
    """
    return _PKG / "data" / "cmu_12_01_walk.bvh"


def mjcf_dir() -> Path:
    """Folder of the bundled MJCF characters.

    Installed wheels carry it as ``physmocap/assets/mjcf``; a source checkout
    (editable install) keeps it at ``assets/mjcf`` beside the package.
    """
    for candidate in (_PKG / "assets" / "mjcf", _PKG.parent / "assets" / "mjcf"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError("physmocap's assets/mjcf folder is missing from this installation")


def resolve_input(path: str | Path) -> Path:
    """``"example"`` means the bundled clip; anything else is a path."""
    if str(path) == EXAMPLE_NAME:
        return example_clip()
    return Path(path)
