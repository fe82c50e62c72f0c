"""`physmocap batch` (issue 14, first part): a folder of clips, resumable, parallel, Ray."""

from __future__ import annotations

import json
import os
import shutil
import time

import pytest

from physmocap.cli import main
from physmocap.resources import resolve_input


@pytest.fixture()
def folder(tmp_path):
    src = resolve_input("example")
    (tmp_path / "in" / "sub").mkdir(parents=True)
    shutil.copy(src, tmp_path / "in" / "a.bvh")
    shutil.copy(src, tmp_path / "in" / "sub" / "b.bvh")
    (tmp_path / "in" / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    return tmp_path


def _batch(folder, out, *extra):
    return main(["batch", str(folder / "in"), "-o", str(folder / out), "--end", "40", "--quiet", *extra])


def _files(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name != "timings.csv"
            and not p.name.startswith(".")}


def test_batch_records_failures_and_mirrors_outputs(folder):
    assert _batch(folder, "out", "--jobs", "1") == 1  # one file failed
    out = folder / "out"
    assert (out / "a.npz").exists() and (out / "sub" / "b.npz").exists() and not (out / "broken.npz").exists()
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["input"]: r for r in summary["files"]}
    assert rows[os.path.join("..", "in", "broken.bvh")]["status"] == "failed"
    assert "broken.bvh" in rows[os.path.join("..", "in", "broken.bvh")]["error"]
    assert rows[os.path.join("..", "in", "a.bvh")]["frames"] == 39
    assert summary["totals"] == {"files": 3, "done": 2, "failed": 1, "frames": 78}


def test_batch_resumes_and_is_the_same_with_more_workers(folder):
    assert _batch(folder, "one", "--jobs", "1") == 1
    first = _files(folder / "one")
    stamp = (folder / "one" / "a.npz").stat().st_mtime_ns
    time.sleep(0.01)
    assert _batch(folder, "one", "--jobs", "1") == 1  # done files are skipped, the failure retried
    assert (folder / "one" / "a.npz").stat().st_mtime_ns == stamp
    assert _files(folder / "one") == first
    assert _batch(folder, "one", "--jobs", "1", "--force") == 1
    assert (folder / "one" / "a.npz").stat().st_mtime_ns != stamp
    assert _batch(folder, "two", "--jobs", "2") == 1
    assert _files(folder / "two") == first
    # other options: the file is redone
    assert _batch(folder, "one", "--jobs", "1", "--no-plant") == 1
    assert _files(folder / "one") != first


def test_batch_on_ray_gives_the_same_files(folder):
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'physmocap[cluster]'")
    assert _batch(folder, "local", "--jobs", "1") == 1
    assert _batch(folder, "ray", "--ray", "local") == 1
    assert _files(folder / "ray") == _files(folder / "local")


def test_batch_bad_source_is_one_clear_error(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nothing"), "-o", str(tmp_path / "o")]) == 2
    assert "folder, a glob" in capsys.readouterr().err
