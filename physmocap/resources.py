"""Locate the files that ship with physmocap: character models and the example clip."""

from __future__ import annotations

import os
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


def display_path(path: str | os.PathLike) -> str:
    """How messages name a file: ``"example"`` for the bundled clip (the name the user gives,
    not its place in this installation), any other path as it is."""
    s = os.fspath(path)
    return EXAMPLE_NAME if s == str(example_clip()) else s


def display_text(text: str) -> str:
    """``text`` (a message) with the bundled clip's installed path shown as ``"example"``."""
    return text.replace(str(example_clip()), EXAMPLE_NAME)


def _bundled_mjcf_names() -> dict[Path, str]:
    d = mjcf_dir()
    return {(d / f"{name}.xml").resolve(): name for name in ("humanoid", "robot") if (d / f"{name}.xml").exists()}


def portable_path(path: str | Path, base: str | Path) -> str:
    """How an output file names another file without the machine's absolute paths:
    ``"example"`` for the bundled clip, the bundled character's name for its MJCF, else the
    path relative to ``base`` (the output's folder), with ``/`` separators.

    The relative path is taken between the paths as given (made absolute, ``..`` folded), not
    through symbolic links: ``../shared/data/walk.bvh`` stays that, whether ``shared`` is a
    folder or a link to one elsewhere on this machine (its target would put this machine's
    layout into the file, and the same command would write other bytes on another)."""
    s = str(path)
    if not s or s.startswith("<"):
        return s
    p = Path(s).resolve()
    if p == example_clip().resolve():
        return EXAMPLE_NAME
    named = _bundled_mjcf_names().get(p)
    if named is not None:
        return named
    try:
        return Path(os.path.relpath(os.path.abspath(s), os.path.abspath(base))).as_posix()
    except ValueError:  # another drive (Windows)
        return Path(os.path.abspath(s)).as_posix()


def resolve_portable(value: str, base: str | Path) -> str:
    """The inverse of :func:`portable_path`: bundled names stay names, relative paths are
    taken from ``base``."""
    p = Path(value)
    if value == EXAMPLE_NAME or (not p.suffix and "/" not in value and os.sep not in value):
        return value
    return str(p if p.is_absolute() else Path(base) / p)
