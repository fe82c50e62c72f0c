"""``physmocap convert``: options, frame ranges, resampling, errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_BVH, shared_file
from physmocap.cli import main
from physmocap.sources import load_motion
from physmocap.sources.bvh import read_bvh


def _run(capsys, *args: str) -> tuple[int, str, str]:
    status = main(list(args))
    out = capsys.readouterr()
    return status, out.out, out.err


def test_convert_example_round_trip(tmp_path, capsys):
    out = tmp_path / "walk.bvh"
    status, stdout, stderr = _run(capsys, "convert", "example", str(out))
    assert status == 0 and stdout == ""
    assert "read" in stderr and "wrote" in stderr
    src, back = load_motion("example"), read_bvh(out)
    np.testing.assert_allclose(back.world_positions(), src.world_positions(), atol=1e-6 * src.skeleton.height())
    assert back.meta["bvh_channels"] == src.meta["bvh_channels"]


@pytest.mark.parametrize("name", SHARED_BVH)
def test_convert_shared_files_with_options(tmp_path, capsys, name):
    src_path = shared_file(name)
    out = tmp_path / "o.bvh"
    status, _, _ = _run(capsys, "convert", str(src_path), str(out), "--rotation-order", "zyx",
                        "--units", "cm", "--up", "Z", "--precision", "7")
    assert status == 0
    text = out.read_text()
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation" in text
    src = read_bvh(src_path)
    back = read_bvh(out, units="cm", up="Z")
    np.testing.assert_allclose(back.world_positions(), src.world_positions(), atol=1e-6 * src.skeleton.height())


def test_frame_range(tmp_path, capsys):
    out = tmp_path / "r.bvh"
    status, _, _ = _run(capsys, "convert", "example", str(out), "--start", "100", "--end", "150")
    assert status == 0
    back = read_bvh(out)
    src = load_motion("example")
    assert back.num_frames == 50
    np.testing.assert_allclose(back.world_positions(), src.world_positions()[100:150], atol=1e-7)
    status, _, _ = _run(capsys, "convert", "example", str(out), "--start", "520")
    assert status == 0 and read_bvh(out).num_frames == 4


@pytest.mark.parametrize("args,needle", [
    (["--start", "600"], "frame range must satisfy 0 <= start < end <= 524"),
    (["--start", "-1"], "--start must be a frame number >= 0"),
    (["--end", "0"], "--end must be a frame number >= 1"),
    (["--start", "10", "--end", "10"], "the range is empty"),
    (["--end", "525"], "frame range must satisfy 0 <= start < end <= 524"),
])
def test_bad_frame_range(tmp_path, capsys, args, needle):
    out = tmp_path / "r.bvh"
    status, stdout, stderr = _run(capsys, "convert", "example", str(out), *args)
    assert status == 2
    assert "physmocap: error:" in stderr and needle in stderr
    assert not out.exists()


def test_resample(tmp_path, capsys):
    out = tmp_path / "r30.bvh"
    status, _, _ = _run(capsys, "convert", "example", str(out), "--fps", "30")
    assert status == 0
    back = read_bvh(out)
    src = load_motion("example")
    assert back.fps == pytest.approx(30.0)
    assert back.num_frames == int(np.floor((src.num_frames - 1) * 30 / src.fps + 1e-9)) + 1
    assert "Frame Time: 0.03333333333" in out.read_text()
    # Frame k at 30 fps is frame ~4k at 120 fps (0.0083333 s frames: within one source frame).
    pos, ref = back.world_positions(), src.world_positions()
    k = 40
    t = k / 30.0
    i = int(round(t * src.fps))
    assert np.abs(pos[k] - ref[i]).max() < 0.03


def test_input_options(tmp_path, capsys):
    out = tmp_path / "u.bvh"
    status, _, stderr = _run(capsys, "convert", "example", str(out), "--in-units", "cm", "--in-up", "y")
    assert status == 0 and "units cm" in stderr
    # Written back in the input's (overridden) unit: the numbers are unchanged.
    src_rows = shared_rows(load_motion("example").source)
    out_rows = shared_rows(out)
    np.testing.assert_allclose(out_rows, src_rows, atol=1e-6)


def shared_rows(path) -> np.ndarray:
    lines = Path(path).read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.strip().startswith("Frame Time"))
    return np.array([ln.split() for ln in lines[i + 1:] if ln.strip()], dtype=float)


@pytest.mark.parametrize("args,message", [
    (["--precision", "99"], "precision must be"),
    (["--rotation-order", "XXY"], "rotation order must be a permutation of XYZ"),
    (["--units", "furlong"], "unknown length unit"),
    (["--in-units", "-3"], "positive"),
    (["--fps", "0"], "--fps must be a positive"),
    (["--fps", "nan"], "--fps must be a positive"),
])
def test_bad_options(tmp_path, capsys, args, message):
    out = tmp_path / "x.bvh"
    status, _, stderr = _run(capsys, "convert", "example", str(out), *args)
    assert status == 2 and message in stderr
    assert not out.exists()


def test_bad_paths(tmp_path, capsys):
    status, _, stderr = _run(capsys, "convert", str(tmp_path / "missing.bvh"), str(tmp_path / "o.bvh"))
    assert status == 2 and "file not found" in stderr
    status, _, stderr = _run(capsys, "convert", "example", str(tmp_path / "o.txt"))
    assert status == 2 and "unknown output type '.txt'" in stderr
    status, _, stderr = _run(capsys, "convert", "example", str(tmp_path / "nodir" / "o.bvh"))
    assert status == 2 and "does not exist" in stderr
    # The output checks run before the (possibly long) input is read.
    assert "read" not in stderr


def test_same_bytes_twice(tmp_path, capsys):
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    for p in (a, b):
        assert _run(capsys, "convert", "example", str(p), "--fps", "60", "--rotation-order", "XYZ")[0] == 0
    assert a.read_bytes() == b.read_bytes()


def test_console_script_no_traceback(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Wrotation\n}\n")
    res = subprocess.run([sys.executable, "-m", "physmocap", "convert", str(bad), str(tmp_path / "o.bvh")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert res.stderr.strip().splitlines()[-1] == (
        f"physmocap: error: {bad}:5: unknown channel 'Wrotation' in joint 'a'; expected 1 of "
        "Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation"
    )
    assert "Traceback" not in res.stderr
