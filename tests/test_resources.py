"""How output files name other files (physmocap.resources.portable_path)."""

from __future__ import annotations

import os

from physmocap.resources import portable_path, resolve_portable


def test_a_path_through_a_symlinked_folder_stays_as_given(tmp_path):
    """Before: the path was made relative through the link's target, so an output named its
    source ``../../real/data/walk.bvh`` when ``shared`` was a link, ``../shared/data/walk.bvh``
    when it was a folder: the same command wrote other bytes on another machine."""
    real = tmp_path / "real" / "data"
    real.mkdir(parents=True)
    (real / "walk.bvh").write_text("x")
    work = tmp_path / "work" / "project"
    work.mkdir(parents=True)
    os.symlink(tmp_path / "real", tmp_path / "work" / "shared")
    out_dir = work / "out"
    out_dir.mkdir()
    given = work / ".." / "shared" / "data" / "walk.bvh"
    stored = portable_path(given, out_dir)
    assert stored == "../../shared/data/walk.bvh"
    assert os.path.samefile(resolve_portable(stored, out_dir), real / "walk.bvh")
