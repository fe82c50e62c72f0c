"""Byte-level edits shared by the readers' property tests (hypothesis ``draw`` based)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Callable

from hypothesis import strategies as st

from physmocap.errors import InputError, PhysmocapWarning


def byte_edit(draw, data: bytes, kind: str) -> bytes:
    """``data`` with one edit of ``kind``: ``"truncate"`` (cut anywhere), ``"flip"`` (one
    bit), ``"dup_line"`` or ``"del_line"`` (a whole line repeated or removed)."""
    out = bytearray(data)
    if not out:
        return bytes(out)
    if kind == "truncate":
        return bytes(out[: draw(st.integers(0, len(out)))])
    if kind == "flip":
        i = draw(st.integers(0, len(out) - 1))
        out[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(out)
    lines = bytes(out).split(b"\n")
    i = draw(st.integers(0, len(lines) - 1))
    if kind == "dup_line":
        lines.insert(i, lines[i])
    elif kind == "del_line":
        del lines[i]
    else:
        raise ValueError(f"unknown edit {kind!r}")
    return b"\n".join(lines)


def read_or_clean_error(read: Callable[[Path], Any], path: Path) -> Any:
    """``read(path)`` with physmocap's warnings silenced, or None when it raised an
    :class:`InputError` whose message is one line naming the file (any other exception
    propagates and fails the test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysmocapWarning)
        try:
            return read(path)
        except InputError as exc:
            msg = str(exc)
            assert msg.startswith(str(path)) and "\n" not in msg
            return None
