"""Every command that takes a recording reads a ``foxglove.PointCloud`` marker MCAP through the
one marker reader (:func:`physmocap.sources.markers.read_markers`), as it reads the C3D the
markers came from; a point cloud without labels is one error naming the file, and nothing is
written (issue 11, deliverable 5)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from physmocap.cli import main
from point_clouds import cloud, cmu_markers, write_cloud_mcap, write_recording_cloud
from test_markers import _c3d_copy

FRAMES = 240


@pytest.fixture(scope="module")
def takes(tmp_path_factory) -> Path:
    """A folder with the CMU take's first frames as ``take.c3d`` and as ``cloud.mcap`` (the same
    samples), and ``nolabels.mcap``, a point cloud whose points are not named."""
    root = tmp_path_factory.mktemp("clouds")
    _c3d_copy(root / "take.c3d", frames=FRAMES)
    write_recording_cloud(root / "cloud.mcap", cmu_markers(FRAMES))
    write_cloud_mcap(root / "nolabels.mcap", [cloud(np.ones((3, 3)))] * 3, 120.0)
    return root


def _run(argv: list[str]) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return main([str(a) for a in argv])


def _inspect(path: Path, capsys) -> dict:
    assert _run(["inspect", path, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    rep.pop("file")
    return rep


def test_inspect_describes_the_cloud_markers_as_the_c3d(takes, capsys):
    cloud_rep = _inspect(takes / "cloud.mcap", capsys)
    assert cloud_rep == _inspect(takes / "take.c3d", capsys)
    assert cloud_rep["frames"] == FRAMES and cloud_rep["roles"]["LKNE"] == "LKNE"
    assert _run(["inspect", takes / "cloud.mcap", "--emit-markerset"]) == 0
    assert 'LKNE = "LKNE"' in capsys.readouterr().out


def test_convert_writes_the_cloud_as_labelled_points_and_the_actor_as_bvh(takes, tmp_path):
    from physmocap.sources.markers import read_markers

    out = tmp_path / "points.mcap"
    assert _run(["convert", takes / "cloud.mcap", out, "--end", "100"]) == 0
    back, want = read_markers(out), read_markers(takes / "take.c3d").frames(0, 100)
    assert back.labels == want.labels and back.fps == want.fps
    assert np.array_equal(back.positions, want.positions, equal_nan=True)
    assert _run(["convert", takes / "cloud.mcap", tmp_path / "actor.bvh"]) == 0
    assert "left_knee" in (tmp_path / "actor.bvh").read_text()


def test_solve_gives_the_c3d_actor(takes, tmp_path):
    a, b = tmp_path / "cloud.bvh", tmp_path / "c3d.bvh"
    assert _run(["solve", takes / "cloud.mcap", "-o", a, "--quiet"]) == 0
    assert _run(["solve", takes / "take.c3d", "-o", b, "--quiet"]) == 0
    assert a.read_bytes() == b.read_bytes()


def test_retarget_and_clean_read_the_cloud(takes, tmp_path, capsys):
    out, report = tmp_path / "o.npz", tmp_path / "glitches.json"
    assert _run(["retarget", takes / "cloud.mcap", "-o", out, "--character", "robot", "--quiet", "--end", "60"]) == 0
    assert np.load(out)["qpos"].shape[0] == 60
    assert _run(["clean", takes / "cloud.mcap", "--report", report]) == 0
    assert json.loads(report.read_text())["frames"] == FRAMES


def test_preview_renders_the_cloud(takes, tmp_path):
    pytest.importorskip("imageio.v2", reason="imageio is not installed: pip install 'physmocap[render]'")
    from physmocap.render.backend import RenderError, ensure_backend

    try:
        ensure_backend()
    except RenderError as exc:
        pytest.skip(f"no OpenGL backend on this machine: {exc}")
    out = tmp_path / "sheet.png"
    assert _run(["preview", takes / "cloud.mcap", "-o", out, "--end", "30", "--count", "2", "--size", "320x240"]) == 0
    assert out.stat().st_size > 0


def test_batch_reads_the_cloud_and_names_the_unlabelled_one(takes, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("cloud.mcap", "nolabels.mcap"):
        (folder / name).write_bytes((takes / name).read_bytes())
    assert _run(["batch", folder, "-o", tmp_path / "out", "--end", "40", "--quiet", "--jobs", "1"]) == 1
    rows = {Path(r["input"]).name: r for r in json.loads((tmp_path / "out" / "summary.json").read_text())["files"]}
    assert rows["cloud.mcap"]["status"] == "done" and rows["cloud.mcap"]["frames"] == 40
    assert rows["nolabels.mcap"]["status"] == "failed"
    assert "nolabels.mcap: /markers is a foxglove.PointCloud without marker labels" in rows["nolabels.mcap"]["error"]
    assert not (tmp_path / "out" / "nolabels.npz").exists()


@pytest.mark.parametrize("argv,outputs", [
    (["inspect", "{IN}"], []),
    (["inspect", "{IN}", "--emit-markerset"], []),
    (["convert", "{IN}", "{OUT}/m.mcap"], ["m.mcap"]),
    (["convert", "{IN}", "{OUT}/a.bvh"], ["a.bvh"]),
    (["solve", "{IN}", "-o", "{OUT}/a.bvh", "--report", "{OUT}/r.json"], ["a.bvh", "r.json"]),
    (["retarget", "{IN}", "-o", "{OUT}/o.bvh", "--qpos", "{OUT}/o.npz"], ["o.bvh", "o.npz"]),
    (["replay", "{IN}", "-o", "{OUT}/o.npz", "--stats", "{OUT}/s.json"], ["o.npz", "s.json"]),
    (["clean", "{IN}", "-o", "{OUT}/c.bvh", "--report", "{OUT}/r.json"], ["c.bvh", "r.json"]),
    (["preview", "{IN}", "-o", "{OUT}/p.png"], ["p.png"]),
], ids=lambda v: v[0] if isinstance(v, list) and v and v[0] != "{IN}" else None)
def test_a_cloud_without_labels_is_one_error_naming_the_file(takes, tmp_path, capsys, argv, outputs):
    args = [a.replace("{IN}", str(takes / "nolabels.mcap")).replace("{OUT}", str(tmp_path)) for a in argv]
    assert _run(args) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "nolabels.mcap: /markers is a foxglove.PointCloud without marker labels" in err[0], err
    assert "Traceback" not in captured.err and captured.out == ""
    assert not any((tmp_path / name).exists() for name in outputs)


def test_report_reads_a_marker_source_as_the_retarget_did(takes, tmp_path):
    """Before: ``report`` re-read a marker source with the default solve whatever the retarget
    had used (no --marker-set, --joint-centres or solve options), so its source figures were
    those of another actor; a marker option on a source that is not a marker file is one error."""
    out, a, b = tmp_path / "o.npz", tmp_path / "a.json", tmp_path / "b.json"
    assert _run(["retarget", takes / "take.c3d", "-o", out, "--joint-centres", "--quiet", "--end", "60"]) == 0
    assert _run(["report", out, "--joint-centres", "--json", a]) == 0
    assert _run(["report", out, "--json", b]) == 0
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    assert ra["source"] != rb["source"]  # the joint centres are not the solved actor
    assert _run(["report", out, "--no-source", "--joint-centres"]) != 0
