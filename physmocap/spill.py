"""Long clips' per-frame arrays kept in temporary files instead of memory.

A spilled array is an ordinary numpy array over a shared mapping of an unlinked temporary
file (:func:`tempfile.TemporaryFile`: no name, removed by the system once unmapped).  Its
pages count in the process's resident memory only while they are mapped in: a page is
mapped when first read or written, and :func:`release` unmaps every page of it (the data
stay in the file; a page touched again is read back from the page cache or the disk).  A
reader that goes through a clip a block of frames at a time and releases after each block
therefore holds one block, not the clip.  Arrays under :data:`SPILL_BYTES` stay in memory
(a short clip costs no file), and so does everything where no temporary file can be made.
"""

from __future__ import annotations

import mmap
import os
import tempfile
import weakref
from typing import Iterator

import numpy as np

__all__ = ["SPILL_BYTES", "spill", "spilled_empty", "release", "blocks", "in_memory", "spilled_copy", "is_spilled"]

#: Arrays of at least this many bytes are spilled (a 10-minute clip's targets are about 40 MB).
SPILL_BYTES = 32 << 20


def _threshold(min_bytes: int | None) -> int:
    """Bytes from which an array is spilled: ``min_bytes``, or :data:`SPILL_BYTES` (read
    when called); at least 1 (an empty array stays in memory)."""
    return max(1, SPILL_BYTES if min_bytes is None else int(min_bytes))


class _SpillMap(mmap.mmap):
    """A mapping this module made (of its own unlinked temporary file): the only kind
    :func:`release` lets go of.  A caller's ``np.memmap`` or ``np.load(..., mmap_mode="c")``
    is not ours: dropping its pages would throw away a copy-on-write mapping's changes."""


#: The mappings of this module alive in the process: while there is none, :func:`release`
#: has nothing to look for (a short clip's or a stream's hundreds of calls a frame).
_LIVE: "weakref.WeakSet[_SpillMap]" = weakref.WeakSet()


def _mapped(nbytes: int, fill: np.ndarray | None = None) -> mmap.mmap | None:
    """A shared, writable mapping of a new unlinked temporary file of ``nbytes`` bytes
    (zeros, or the bytes of the C-contiguous ``fill`` written through the file, so no page
    of it is mapped in); None where the file cannot be made.  The zeros' disk blocks are
    reserved up front where the system can (a full disk then refuses here, instead of
    failing a write through the mapping later)."""
    try:
        with tempfile.TemporaryFile(prefix="physmocap-") as fh:
            if fill is None and hasattr(os, "posix_fallocate"):
                os.posix_fallocate(fh.fileno(), 0, nbytes)
            elif fill is None:
                fh.truncate(nbytes)
            else:
                fill.tofile(fh)
            fh.flush()
            mapping = _SpillMap(fh.fileno(), nbytes)
            _LIVE.add(mapping)
            return mapping
    except (OSError, ValueError):
        return None


def spill(array: np.ndarray, min_bytes: int | None = None) -> np.ndarray:
    """A read-only copy of ``array`` in a temporary file (the same values, shape and dtype,
    C-ordered); ``array`` itself if it is smaller than ``min_bytes`` (default
    :data:`SPILL_BYTES`) or cannot be spilled, a read-only view of it if it is spilled already."""
    if array.nbytes < _threshold(min_bytes):
        return array
    if _mapping(array) is not None and array.flags.c_contiguous:
        view = array.view()
        view.flags.writeable = False
        return view
    if not array.flags.c_contiguous:  # copied a block of rows at a time: never held whole
        out = spilled_copy(array, min_bytes)
        if _mapping(out) is None:
            return array
        out.flags.writeable = False
        return out
    data = array
    mapping = _mapped(data.nbytes, data)
    if mapping is None:
        return array
    out = np.frombuffer(mapping, dtype=data.dtype).reshape(data.shape)
    out.flags.writeable = False
    return out


def spilled_empty(shape: tuple[int, ...], dtype=np.float64, min_bytes: int | None = None, by_column: bool = False) -> np.ndarray:
    """A writable array of zeros in a temporary file (in memory, ``np.zeros``, if smaller
    than ``min_bytes``, default :data:`SPILL_BYTES`, or where no file can be made).
    C-ordered, or with ``by_column`` laid out column by column (the first two axes swapped
    in memory: ``array[:, k]`` is contiguous, so a reader that goes through the columns maps
    in one at a time)."""
    if by_column:
        return spilled_empty((shape[1], shape[0], *shape[2:]), dtype, min_bytes).swapaxes(0, 1)
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    mapping = _mapped(nbytes) if nbytes >= _threshold(min_bytes) else None
    if mapping is None:
        return np.zeros(shape, dtype=dtype)
    return np.frombuffer(mapping, dtype=dtype).reshape(shape)


def _mapping(array: np.ndarray | None) -> mmap.mmap | None:
    """The mapping of a temporary file of this module under ``array`` (a spilled array or a
    view of one), or None (any other array, a caller's memory-mapped file included)."""
    base = array
    while isinstance(base, np.ndarray):
        base = base.base
    if isinstance(base, memoryview):  # np.frombuffer's view of the mapping
        base = base.obj
    return base if isinstance(base, _SpillMap) and not base.closed else None


def is_spilled(array: np.ndarray | None) -> bool:
    """Whether ``array`` (or the array it is a view of) lives in a temporary file."""
    return _mapping(array) is not None


def release(array: np.ndarray | None) -> None:
    """Unmap the pages of the temporary file under ``array`` (or any view of a spilled
    array) from this process: they leave its resident memory, and their data stay in the
    file.  Nothing for an array in memory."""
    if not _LIVE:
        return
    mapping = _mapping(array)
    if mapping is not None and hasattr(mmap, "MADV_DONTNEED"):  # not on Windows: the pages stay
        mapping.madvise(mmap.MADV_DONTNEED)


#: Rows :func:`blocks` hands out at a time.
BLOCK_ROWS = 8192


def blocks(array: np.ndarray, rows: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """``(first row, array[first : first + rows])`` for consecutive blocks of ``array``'s
    rows (default :data:`BLOCK_ROWS`), the pages read so far released after each block
    (:func:`release`): a spilled array is gone through holding one block of it."""
    rows = BLOCK_ROWS if rows is None else int(rows)
    for s in range(0, array.shape[0], rows):
        yield s, array[s : s + rows]
        release(array)


def _copy_rows(out: np.ndarray, array: np.ndarray) -> np.ndarray:
    """``out`` with ``array``'s rows copied into it :data:`BLOCK_ROWS` at a time, the pages
    of either that is spilled let go after each block."""
    for s, rows in blocks(array):
        out[s : s + rows.shape[0]] = rows
        release(out)
    return out


def in_memory(array: np.ndarray) -> np.ndarray:
    """A C-ordered copy of ``array`` in memory, read :data:`BLOCK_ROWS` rows at a time (a
    spilled array's pages let go after each block: only the copy is held)."""
    return _copy_rows(np.empty(array.shape, dtype=array.dtype), array)


def spilled_copy(array: np.ndarray, min_bytes: int | None = None, by_column: bool = False) -> np.ndarray:
    """A writable copy of ``array`` (any layout) laid out as :func:`spilled_empty` lays it out
    (C-ordered, or column by column), in a temporary file if it has ``min_bytes`` or more,
    copied a block of rows at a time: neither it nor a spilled ``array`` is ever held whole."""
    return _copy_rows(spilled_empty(array.shape, array.dtype, min_bytes, by_column), array)
