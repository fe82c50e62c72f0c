"""Atomic output files: write to a temporary file beside the target, then rename.

A failed or interrupted write never leaves a half-written output file, and an
existing file at the target path is only replaced once the new one is complete.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

from .errors import OutputError


def check_writable(path: str | os.PathLike) -> Path:
    """Fail early, with a clear error, if ``path`` cannot be written."""
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise OutputError("output path is a directory, expected a file name", path=p)
    if not parent.exists():
        raise OutputError(f"output directory {str(parent)!r} does not exist", path=p)
    if not os.access(parent, os.W_OK):
        raise OutputError(f"output directory {str(parent)!r} is not writable", path=p)
    return p


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file for writing; rename it over ``path`` on success.

    ``mode`` is ``"w"`` (text, UTF-8, ``\\n`` newlines unless ``newline`` given)
    or ``"wb"``.  On any exception the temporary file is removed and ``path``
    is left untouched.
    """
    if mode not in ("w", "wb"):
        raise ValueError("atomic_open supports modes 'w' and 'wb'")
    p = check_writable(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent or ".")
    except OSError as exc:
        raise OutputError(f"cannot create a file here: {exc.strerror}", path=p) from None
    try:
        if mode == "w":
            kwargs.setdefault("encoding", "utf-8")
            kwargs.setdefault("newline", "\n")
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
