"""The shared clips a script is asked for (``--clips``), resolved before any work.

A clip is a file name in the data folder (``PHYSMOCAP_SHARED_DATA``, default
``../shared/data``), with or without its ``.bvh`` suffix.  A clip named on the command line
that is not there stops the script with status 2 (a typo must not pass as a clean run);
clips of the script's default list that are absent are skipped, each said on stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Sequence


def find_clip(data: Path, name: str) -> Path | None:
    """``data / name``, or ``data / (name + ".bvh")`` for a name without a suffix; None when
    neither is a file."""
    for candidate in (data / name, data / f"{name}.bvh"):
        if candidate.is_file():
            return candidate
        if Path(name).suffix:
            break
    return None


def resolve_clips(data: Path, named: Sequence[str] | None, default: Sequence[str], script: str) -> list[Path]:
    """The paths of the ``named`` clips (every one must exist: else exit 2 naming the missing),
    or of the ``default`` ones found (the others skipped with a line on stderr); exit 2 too
    when no clip is left."""
    if named:
        found = {name: find_clip(data, name) for name in named}
        missing = [name for name, path in found.items() if path is None]
        if missing:
            _fail(f"{script}: error: clip(s) not found in {data}: {', '.join(missing)}")
        return [found[name] for name in named]
    paths = []
    for name in default:
        path = find_clip(data, name)
        if path is None:
            print(f"skip {name}: {data / name} not found", file=sys.stderr)
        else:
            paths.append(path)
    if not paths:
        _fail(f"{script}: error: none of the clips found in {data} (set PHYSMOCAP_SHARED_DATA)")
    return paths


def _fail(message: str) -> None:
    """Say ``message`` on stderr and exit with status 2 (the CLI's status for bad arguments)."""
    print(message, file=sys.stderr)
    raise SystemExit(2)
