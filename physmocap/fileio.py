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


def check_not_input(outputs, inputs) -> None:
    """Refuse an output path that is one of the inputs (a run must never overwrite its capture)."""
    ins = [Path(i) for i in inputs if i is not None]
    for out in outputs:
        if out is None:
            continue
        o = Path(out)
        for i in ins:
            same = o.resolve() == i.resolve()
            if not same and o.exists() and i.exists():
                same = os.path.samefile(o, i)
            if same:
                raise OutputError("the output is the input file: choose another output path", path=o)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, keep_suffix: bool = True) -> Iterator[Path]:
    """A temporary file beside ``path`` (with the same suffix, for writers that pick a
    format from the name, such as video encoders), renamed over ``path`` when the
    ``with`` block succeeds and removed on any exception, leaving ``path`` untouched."""
    p = check_writable(path)
    suffix = f".tmp{p.suffix}" if keep_suffix else ".tmp"
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=suffix, dir=p.parent or ".")
    except OSError as exc:
        raise OutputError(f"cannot create a file here: {exc.strerror}", path=p) from None
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file for writing; rename it over ``path`` on success.

    ``mode`` is ``"w"`` (text, UTF-8, ``\\n`` newlines unless ``newline`` given)
    or ``"wb"``.  On any exception the temporary file is removed and ``path``
    is left untouched (:func:`atomic_path`).
    """
    if mode not in ("w", "wb"):
        raise ValueError("atomic_open supports modes 'w' and 'wb'")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
        kwargs.setdefault("newline", "\n")
    with atomic_path(path, keep_suffix=False) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def read_toml(path: str | os.PathLike, kind: str = "mapping file") -> tuple[dict, str]:
    """Read a TOML file: ``(data, text)``; clear :class:`InputError` naming the file and line.

    ``kind`` names the file in messages (``"mapping file"``...).  Uses the standard
    library's ``tomllib`` (Python 3.11+) or ``tomli`` on 3.10.
    """
    import re

    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    from .errors import InputError

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{kind} not found", path=p) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected a {kind} (TOML)", path=p) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {kind}: {exc}", path=p) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"at line (\d+)", str(exc))
        raise InputError(f"not valid TOML: {exc}", path=p, line=int(m.group(1)) if m else None) from None
