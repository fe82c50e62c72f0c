"""Malformed BVH files: one clear InputError naming the file, the line and what
was expected; Frames: mismatches warn and read what is there; the CLI exits 2."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from conftest import first_frames, shared_file
from physmocap.errors import InputError, PhysmocapWarning
from physmocap.sources import load_motion
from physmocap.sources.bvh import read_bvh

FIXTURES = Path(__file__).parent / "fixtures" / "bvh"
SRC = first_frames("optitrack_motive.bvh", 5)
LINES = SRC.split(b"\n")
MOTION = LINES.index(b"MOTION")  # 0-based index; MOTION is on line MOTION + 1
FIRST_ROW = MOTION + 3  # 0-based index of the first frame row
NCH = len(LINES[FIRST_ROW].split())


def _write(tmp_path: Path, data: bytes) -> Path:
    p = tmp_path / "bad.bvh"
    p.write_bytes(data)
    return p


def _row_edit(k: int, fn) -> bytes:
    lines = list(LINES)
    lines[FIRST_ROW + k] = fn(lines[FIRST_ROW + k])
    return b"\n".join(lines)


def _replace_value(k: int, col: int, token: bytes) -> bytes:
    def fn(line: bytes) -> bytes:
        toks = line.split()
        toks[col] = token
        return b" ".join(toks)

    return _row_edit(k, fn)


# (case id, file bytes, expected 1-based line or None, regex the message must match)
CASES = [
    ("empty", b"", None, r"empty file; expected .*HIERARCHY"),
    ("whitespace only", b" \n\t\n", 1, r"empty file"),
    ("binary", bytes(range(256)) * 8, 1, r"binary file .*expected a BVH text file"),
    ("not utf-8", SRC.replace(b"LeftHand", b"LeftH\xe4nd", 1), 40, r"not UTF-8 .*0xe4"),
    ("utf-16", SRC.decode().encode("utf-16"), 1, r"UTF-16"),
    ("not bvh (csv)", b"frame,x,y,z\n0,1,2,3\n", 1, r"not a BVH file: expected 'HIERARCHY'"),
    ("not bvh (json)", b'{"HIERARCHY": 1}', 1, r"not a BVH file"),
    ("missing MOTION", b"\n".join(LINES[:MOTION]), MOTION, r"missing MOTION section"),
    ("hierarchy only to EOF", b"\n".join(LINES[:20]), 20, r"unbalanced braces: the file ends inside joint"),
    ("extra open brace", SRC.replace(b"    JOINT Spine\n    {\n", b"    JOINT Spine\n    {\n    {\n", 1), 8,
     r"unbalanced braces: unexpected '\{'"),
    ("extra close brace", SRC.replace(b"MOTION", b"}\nMOTION"), MOTION + 1, r"unbalanced braces: '\}' without"),
    ("missing close brace", SRC.replace(b"}\nMOTION", b"MOTION"), MOTION, r"unbalanced braces: MOTION inside joint 'Hips'"),
    ("unknown channel", SRC.replace(b"Zrotation", b"Qrotation", 1), 5, r"unknown channel 'Qrotation' in joint 'Hips'"),
    ("channel listed twice", SRC.replace(b"Zrotation Xrotation Yrotation", b"Zrotation Zrotation Yrotation", 1), 5,
     r"channel Zrotation listed twice"),
    ("too many channels", SRC.replace(b"CHANNELS 6", b"CHANNELS 7", 1), 5, r"number of channels \(0 to 6\)"),
    ("channel count word", SRC.replace(b"CHANNELS 6", b"CHANNELS six", 1), 5, r"number of channels"),
    ("bad offset", SRC.replace(b"OFFSET 0.000000 7.900000", b"OFFSET 0.000000 7.9x", 1), 8,
     r"expected a number for OFFSET Y of joint 'Spine'"),
    ("nan offset", SRC.replace(b"OFFSET 0.000000 7.900000", b"OFFSET 0.000000 nan", 1), 8, r"expected a finite number"),
    ("missing offset", SRC.replace(b"        OFFSET 0.000000 7.900000 0.000000\n", b"", 1), 9,
     r"joint 'Spine' \(line 6\) has no OFFSET before its children; expected 'OFFSET x y z'"),
    ("missing channels", SRC.replace(b"        CHANNELS 3 Zrotation Xrotation Yrotation\n", b"", 1), 9,
     r"joint 'Spine' \(line 6\) has no CHANNELS"),
    ("leaf without offset", SRC.replace(b"                        OFFSET 0.000000 19.200000 0.000000\n", b"", 1), 24,
     r"an End Site \(line 22\) has no OFFSET"),
    ("joint without name", SRC.replace(b"JOINT Spine\n", b"JOINT\n", 1), 6, r"expected a joint name after JOINT"),
    ("typo keyword", SRC.replace(b"JOINT Spine1", b"JIONT Spine1", 1), 10, r"unexpected 'JIONT' in joint 'Spine'"),
    ("end without site", SRC.replace(b"End Site", b"End Sight", 1), None, r"expected 'End Site'"),
    ("no frames line", SRC.replace(b"Frames:    5\n", b""), MOTION + 3, r"expected 'Frames: <count>'"),
    ("frames not a number", SRC.replace(b"Frames:    5", b"Frames: five"), MOTION + 2,
     r"whole number of frames after 'Frames:', found 'five'"),
    ("no frame time", SRC.replace(b"Frame Time:    0.008333", b""), MOTION + 4, r"expected 'Frame Time: <seconds>'"),
    ("frame time zero", SRC.replace(b"Frame Time:    0.008333", b"Frame Time: 0"), MOTION + 3,
     r"Frame Time is 0; expected a positive"),
    ("frame time text", SRC.replace(b"Frame Time:    0.008333", b"Frame Time: fast"), MOTION + 3,
     r"expected a number of seconds"),
    ("ends after MOTION", b"\n".join(LINES[: MOTION + 1]), MOTION + 1, r"file ends early: expected 'Frames"),
    ("truncated middle row", _row_edit(1, lambda ln: ln[:40]), FIRST_ROW + 2,
     rf"frame 1: expected {NCH} numbers \(one per channel\), found \d+"),
    ("extra value", _row_edit(2, lambda ln: ln + b" 1.0"), FIRST_ROW + 3, rf"frame 2: expected {NCH} numbers.*found {NCH + 1}"),
    ("non-numeric token", _replace_value(2, 7, b"abc"), FIRST_ROW + 3,
     r"frame 2: expected a number for Spine Xrotation \(value 8\), found 'abc'"),
    ("two dots", _replace_value(0, 3, b"1.2.3"), FIRST_ROW + 1, r"found '1\.2\.3'"),
    ("comma decimal", _replace_value(0, 3, b"1,5"), FIRST_ROW + 1, r"found '1,5'"),
    ("nan value", _replace_value(3, 4, b"nan"), FIRST_ROW + 4, r"frame 3: Hips Xrotation \(value 5\) is 'nan'; expected a finite"),
    ("inf value", _replace_value(1, 0, b"-inf"), FIRST_ROW + 2, r"Hips Xposition \(value 1\) is '-inf'"),
    ("overflow", _replace_value(1, 0, b"1e400"), FIRST_ROW + 2, r"out of range"),
    ("NUL in data", _replace_value(4, 10, b"1\x002"), FIRST_ROW + 5, r"expected a number"),
    ("non-ascii in data", _replace_value(4, 10, "1·2".encode()), FIRST_ROW + 5, r"expected a number"),
    ("text after rows", SRC + b"THE END\n", FIRST_ROW + 6, r"frame 5: expected a number for Hips Xposition.*'THE'"),
    ("no channels at all", b"HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n}\nMOTION\nFrames: 1\nFrame Time: 1\n\n",
     2, r"declares no channels"),
    ("no ROOT", b"HIERARCHY\nMOTION\nFrames: 0\nFrame Time: 1\n", 2, r"has no ROOT"),
    ("end site with channels",
     b"HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\nEnd Site\n{\nOFFSET 0 1 0\nCHANNELS 1 Xrotation\n}\n}\n",
     9, r"End Site has channels"),
]


@pytest.mark.parametrize("data,line,pattern", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_malformed_file_gives_one_clear_error(tmp_path, data, line, pattern):
    path = _write(tmp_path, data)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)  # an error, not a warning
        with pytest.raises(InputError) as info:
            read_bvh(path)
    err = info.value
    msg = str(err)
    assert err.path == str(path)
    assert msg.startswith(str(path))
    if line is not None:
        assert err.line == line, msg
        assert msg.startswith(f"{path}:{line}: "), msg
    assert re.search(pattern, msg), msg
    assert "\n" not in msg


def test_error_messages_on_real_file(tmp_path):
    """A corrupted copy of a real recording (CRLF, tabs) reports the right line."""
    src = shared_file("cmu_12_01_walk.bvh").read_bytes()
    lines = src.split(b"\n")
    k = lines.index(b"Frame Time: .0083333") + 101  # frame 100
    toks = lines[k].split(b" ")
    toks[20] = b"oops"
    lines[k] = b" ".join(toks)
    with pytest.raises(InputError, match=rf":{k + 1}: frame 100: expected a number for .* found 'oops'"):
        read_bvh(_write(tmp_path, b"\n".join(lines)))


# -- Frames: disagreeing with the rows -----------------------------------------------


def test_frames_larger_than_rows_warns(tmp_path):
    path = _write(tmp_path, SRC.replace(b"Frames:    5", b"Frames: 9"))
    with pytest.warns(PhysmocapWarning, match=r"'Frames: 9' but the file has 5 frame rows; read the 5"):
        m = read_bvh(path)
    assert m.num_frames == 5


def test_frames_smaller_than_rows_warns(tmp_path):
    path = _write(tmp_path, SRC.replace(b"Frames:    5", b"Frames: 2"))
    with pytest.warns(PhysmocapWarning, match=r"'Frames: 2' but the file has 5"):
        m = read_bvh(path)
    assert m.num_frames == 5


def test_huge_frames_count_does_not_allocate(tmp_path):
    path = _write(tmp_path, SRC.replace(b"Frames:    5", b"Frames: 99999999999999"))
    with pytest.warns(PhysmocapWarning):
        m = read_bvh(path)
    assert m.num_frames == 5


@pytest.mark.parametrize("newline", [b"", b"\n", b"\r\n"])
def test_truncated_file_is_an_error_naming_the_line(tmp_path, newline):
    """The file ends in the middle of a row (a truncated row): one clear error."""
    body = b"\n".join(LINES[: FIRST_ROW + 4]) + b"\n" + LINES[FIRST_ROW + 4][:57] + newline
    with pytest.raises(InputError, match=rf":{FIRST_ROW + 5}: frame 4: expected {NCH} numbers.*truncated"):
        read_bvh(_write(tmp_path, body))


def test_short_last_row_beyond_frames_is_an_error(tmp_path):
    """A short last row that Frames: does not need is not a truncation: error."""
    body = SRC.replace(b"Frames:    5", b"Frames: 4")
    body = b"\n".join(body.split(b"\n")[: FIRST_ROW + 4]) + b"\n" + LINES[FIRST_ROW + 4][:57] + b"\n"
    with pytest.raises(InputError, match=rf":{FIRST_ROW + 5}: frame 4: expected {NCH} numbers"):
        read_bvh(_write(tmp_path, body))


def test_short_row_then_more_rows_across_chunks(tmp_path, monkeypatch):
    """A short row at a chunk's end that is followed by more rows is an error."""
    from physmocap.sources import bvh as bvh_mod

    monkeypatch.setattr(bvh_mod, "CHUNK_BYTES", 64)
    data = _row_edit(2, lambda ln: ln[:30])
    with pytest.raises(InputError, match=rf":{FIRST_ROW + 3}: frame 2: expected {NCH} numbers"):
        read_bvh(_write(tmp_path, data))


def test_duplicate_joint_names_are_renamed_with_warning(tmp_path):
    data = SRC.replace(b"JOINT Spine1", b"JOINT Spine", 1)
    with pytest.warns(PhysmocapWarning, match=r"joint name 'Spine' is used twice; renamed it Spine_2"):
        m = read_bvh(_write(tmp_path, data))
    assert "Spine_2" in m.skeleton.names


def test_loader_errors(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        load_motion(tmp_path / "missing.bvh")
    (tmp_path / "d.bvh").mkdir()
    with pytest.raises(InputError, match="directory"):
        load_motion(tmp_path / "d.bvh")


# -- the command line -----------------------------------------------------------------


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "physmocap", *args], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize("case", ["truncated middle row", "binary", "missing MOTION", "nan value"])
def test_cli_reports_bad_input_in_one_line(tmp_path, case):
    data = next(c[1] for c in CASES if c[0] == case)
    path = _write(tmp_path, data)
    out = tmp_path / "out.bvh"
    res = _cli("convert", str(path), str(out))
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("physmocap: error:")]
    assert len(lines) == 1 and str(path) in lines[0]
    assert res.stdout == ""
    assert not out.exists()
