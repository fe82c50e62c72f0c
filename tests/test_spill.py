"""Arrays kept in temporary files (issue 14, bounded memory): the same numbers as in memory,
and a retarget with everything spilled writes the same bytes as one with nothing spilled."""

from __future__ import annotations

import importlib
import warnings

import numpy as np
import pytest

import physmocap.spill as spill_mod
from physmocap.cli import main as cli_main
from physmocap.spill import blocks, in_memory, release, spill, spilled_empty


def test_spilled_arrays_keep_their_values_after_release():
    a = np.arange(3000.0).reshape(1000, 3)
    b = spill(a, min_bytes=1)
    assert b is not a and not b.flags.writeable and np.array_equal(a, b)
    release(b[10:])  # a view's mapping is the array's
    assert np.array_equal(a, b)
    assert spill(a) is a  # under SPILL_BYTES: kept in memory
    c = spilled_empty((1000, 3), min_bytes=1)
    for s, rows in blocks(c, rows=64):
        rows[:] = a[s : s + rows.shape[0]]
    release(c)
    assert np.array_equal(c, a) and np.array_equal(in_memory(c), a)
    assert spill(c, min_bytes=1).base is not None and np.shares_memory(spill(c, min_bytes=1), c)  # spilled already


def _retarget(tmp_path, name: str) -> tuple[bytes, bytes]:
    out = tmp_path / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cli_main(["retarget", "example", "--end", "240", "-o", str(out.with_suffix(".bvh")),
                  "--qpos", str(out.with_suffix(".npz")), "--quiet"])
    return out.with_suffix(".bvh").read_bytes(), out.with_suffix(".npz").read_bytes()


@pytest.mark.parametrize("rows", [7, 8192])
def test_everything_spilled_writes_the_same_bytes(tmp_path, monkeypatch, rows):
    """Every array spilled (and the tracker's, writers' and readers' blocks tiny): the BVH
    and NPZ are byte for byte those of a retarget held in memory."""
    kept = _retarget(tmp_path, "kept")
    monkeypatch.setattr(spill_mod, "SPILL_BYTES", 1)
    monkeypatch.setattr(spill_mod, "BLOCK_ROWS", rows)
    monkeypatch.setattr(importlib.import_module("physmocap.ik.retarget"), "RELEASE_FRAMES", rows)
    assert _retarget(tmp_path, "spilled") == kept


def test_is_spilled_tells_a_temporary_file_from_memory():
    import numpy as np

    from physmocap.spill import is_spilled, spilled_empty

    on_disk = spilled_empty((64,), min_bytes=1)
    assert is_spilled(on_disk) and is_spilled(on_disk[8:16])
    assert not is_spilled(np.zeros(64)) and not is_spilled(spilled_empty((4,), min_bytes=1 << 30))


def test_spilled_copy_keeps_values_in_either_layout():
    """spilled_copy: the same values, C-ordered or laid out column by column (each column
    contiguous), in a temporary file from min_bytes on; spill() of an array in any layout
    is a C-ordered spilled copy, made a block of rows at a time."""
    from physmocap.spill import is_spilled, spilled_copy

    a = np.arange(5 * 4 * 3, dtype=float).reshape(5, 4, 3)
    strided = a.transpose(1, 0, 2)  # not C-contiguous
    for src in (a, strided):
        c = spilled_copy(src, min_bytes=1)
        assert is_spilled(c) and c.flags.c_contiguous and c.flags.writeable and np.array_equal(c, src)
        k = spilled_copy(src, min_bytes=1, by_column=True)
        assert is_spilled(k) and np.array_equal(k, src)
        assert k[:, 2].flags.c_contiguous and not k.flags.c_contiguous
        s = spill(src, min_bytes=1)
        assert is_spilled(s) and s.flags.c_contiguous and not s.flags.writeable and np.array_equal(s, src)
    assert not is_spilled(spilled_copy(a)) and np.array_equal(spilled_copy(a), a)  # small: in memory
    assert spill(strided) is strided



def test_a_callers_memory_mapped_file_is_not_ours_to_release(tmp_path):
    """Before: any array over an mmap counted as spilled, so going through a caller's
    ``np.load(..., mmap_mode="c")`` array a block at a time dropped its pages, and with them
    the caller's copy-on-write changes (a motion's rotations reset to the file's)."""
    from physmocap.spill import blocks, is_spilled

    path = tmp_path / "a.npy"
    np.save(path, np.zeros((20000, 4)))
    m = np.load(path, mmap_mode="c")
    m[:] = -1.0
    assert not is_spilled(m)
    for _ in blocks(m, rows=1000):
        pass
    assert np.all(m == -1.0)
