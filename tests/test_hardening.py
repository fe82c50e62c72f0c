"""Hardening (issue 15, first part): one clear line for every bad input or environment failure."""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import subprocess
import sys

import pytest

from physmocap.cli import main
from physmocap.resources import resolve_input
from conftest import RETARGET_DIAGNOSTICS

pytestmark = RETARGET_DIAGNOSTICS

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  End Site
  {
    OFFSET 0 10 0
  }
}
MOTION
Frames: 2
Frame Time: FT
0 90 0 0 0 0
0 90 0 0 0 0
"""


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("physmocap: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_help_imports_neither_numpy_stack_nor_mujoco():
    """`physmocap --help` must start fast: the command table loads no scipy, MuJoCo or mink."""
    code = (
        "import sys; from physmocap.cli import build_parser; build_parser(); "
        "print(','.join(m for m in ('scipy', 'mujoco', 'mink') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "", out.stdout + out.stderr


@pytest.mark.parametrize("command", ["convert", "retarget", "clean"])
def test_output_that_is_the_input_is_refused(tmp_path, capsys, command):
    src = tmp_path / "walk.bvh"
    original = resolve_input("example").read_bytes()
    src.write_bytes(original)
    argv = [command, str(src), str(src)] if command == "convert" else [command, str(src), "-o", str(src)]
    assert main(argv) == 2
    assert "the output is the input file" in _one_line(capsys)
    assert src.read_bytes() == original


def test_sigterm_removes_the_half_written_output(tmp_path, monkeypatch, capsys):
    """SIGTERM (kill, timeout, a scheduler) ends a command as Ctrl-C does: its half-written
    output is removed (a killed preview left a hidden partial video) and it exits 143."""
    import signal

    import physmocap.cli.convert as convert
    from physmocap.fileio import atomic_open

    out = tmp_path / "walk.bvh"

    def writes_then_is_killed(args):
        with atomic_open(out) as fh:
            fh.write("HIERARCHY\n")
            os.kill(os.getpid(), signal.SIGTERM)
        return 0

    monkeypatch.setattr(convert, "run", writes_then_is_killed)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["convert", "example", str(out)]) == 143
    assert "physmocap: terminated" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) is before  # put back for a program that calls main


def test_a_caller_s_own_sigterm_handling_is_kept(monkeypatch):
    """A program that calls main with SIGTERM ignored (or handled itself) keeps it so: main
    installs its own only over the default action."""
    import signal

    import physmocap.cli.convert as convert

    seen = []
    monkeypatch.setattr(convert, "run", lambda args: seen.append(signal.getsignal(signal.SIGTERM)) or 0)
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        assert main(["convert", "example", os.devnull]) == 0
        assert seen == [signal.SIG_IGN]
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)


@pytest.mark.parametrize("flag", ["-o", "--stats"])
def test_replay_never_overwrites_its_recording(tmp_path, capsys, flag):
    src = tmp_path / "walk.bvh"
    original = resolve_input("example").read_bytes()
    src.write_bytes(original)
    assert main(["replay", str(src), flag, str(src)]) == 2
    assert "the output is the input file" in _one_line(capsys)
    assert src.read_bytes() == original


def test_report_never_overwrites_its_trajectory(tmp_path, capsys):
    traj = tmp_path / "walk.npz"
    assert main(["retarget", "example", "-o", str(traj), "--end", "20", "--quiet"]) == 0
    capsys.readouterr()
    original = traj.read_bytes()
    assert main(["report", str(traj), "--json", str(traj)]) == 2
    assert "the output is the input file" in _one_line(capsys)
    assert traj.read_bytes() == original


@pytest.mark.parametrize("options", [["--calibration-seconds", "-1"], ["--marker-set", "set.toml"], ["--calibrate", "rom.c3d"]])
def test_replay_refuses_marker_options_on_a_skeleton(tmp_path, capsys, options):
    assert main(["replay", "example", *options]) == 2
    assert "for marker recordings only" in _one_line(capsys)


@pytest.mark.parametrize("ft,needle", [("1e-300", "frame rate"), ("0.000001", "frame rate"), ("100", "frame rate")])
def test_implausible_frame_rates_are_refused(tmp_path, capsys, ft, needle):
    path = tmp_path / "odd.bvh"
    path.write_text(BVH.replace("FT", ft))
    assert main(["convert", str(path), str(tmp_path / "out.bvh")]) == 2
    line = _one_line(capsys)
    assert needle in line and "odd.bvh" in line
    assert not (tmp_path / "out.bvh").exists()


def test_far_offsets_are_refused(tmp_path, capsys):
    path = tmp_path / "far.bvh"
    path.write_text(BVH.replace("FT", "0.033").replace("OFFSET 0 10 0", "OFFSET 0 5e6 0"))
    assert main(["inspect", str(path), "--in-units", "m"]) == 2
    line = _one_line(capsys)
    assert "far.bvh" in line and "within 1 km" in line


def test_file_too_large_is_one_line(tmp_path):
    """An OSError while writing (disk full, quota, ulimit -f) is one line with exit 2 and leaves
    no partial file."""
    out = tmp_path / "walk.npz"

    def limit():  # 64 KB per file: the trajectory NPZ is larger
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, 64 * 1024))

    r = subprocess.run(
        [sys.executable, "-m", "physmocap", "retarget", "example", "-o", str(out), "--end", "40", "--quiet"],
        capture_output=True, text=True, timeout=300, preexec_fn=limit,
    )
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("physmocap: error:")]
    assert r.returncode == 2 and len(errors) == 1 and "Traceback" not in r.stderr, r.stderr
    assert not out.exists() and not list(tmp_path.glob(".*tmp*"))


@pytest.mark.parametrize("command", [
    ["retarget", "example", "-o", "{out}", "--qpos", "{tmp}/walk.npz", "--end", "40"],
    ["convert", "example", "{out}"],
    ["clean", "example", "-o", "{out}"],
])
def test_file_too_large_names_the_output(tmp_path, command):
    """Over ``ulimit -f`` (Python ignores SIGXFSZ, so the write fails with EFBIG) the one error
    line names the output being written, not a bare 'File too large', and no file is left."""
    out = tmp_path / "big.bvh"
    argv = [a.format(out=out, tmp=tmp_path) for a in command]

    def limit():  # 16 KB per file: every output here is larger
        resource.setrlimit(resource.RLIMIT_FSIZE, (16 * 1024, 16 * 1024))

    r = subprocess.run([sys.executable, "-m", "physmocap", *argv], capture_output=True, text=True, timeout=300,
                       preexec_fn=limit)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("physmocap: error:")]
    assert r.returncode == 2 and len(errors) == 1 and "Traceback" not in r.stderr, r.stderr
    assert errors[0].startswith("physmocap: error: ") and "File too large" in errors[0] and "ulimit -f" in errors[0]
    assert str(out) in errors[0] or str(tmp_path / "walk.npz") in errors[0], errors[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("code", [errno.EFBIG, errno.ENOSPC, errno.EIO])
def test_write_errors_name_the_final_output(tmp_path, code):
    """An OSError while a writer fills its temporary file is an OutputError naming the output
    (never the temporary sibling), and the temporary file is gone."""
    from physmocap.errors import OutputError
    from physmocap.fileio import OutputSet, atomic_open

    out = tmp_path / "o.json"
    for in_set in (False, True):
        with pytest.raises(OutputError) as info:
            with OutputSet() if in_set else contextlib.nullcontext():
                with atomic_open(out) as fh:
                    fh.write("{")
                    raise OSError(code, os.strerror(code))
        assert str(info.value).startswith(f"{out}: not written: {os.strerror(code)}")
        assert ".tmp" not in str(info.value) and list(tmp_path.iterdir()) == []


def test_fuzz_smoke():
    """A short run of the repository's fuzzing campaign (scripts/fuzz.py runs it for hours)."""
    import io
    import runpy

    from conftest import REPO

    fuzz = runpy.run_path(str(REPO / "scripts" / "fuzz.py"), run_name="fuzz")
    log = io.StringIO()
    counts = fuzz["campaign"](cases=10, seconds=0.0, seed=7, keep=None, out=log)
    assert sum(counts.values()) == 10
    assert not any(outcome == "FAIL" for (_, outcome) in counts), log.getvalue()


def test_outputs_carry_no_absolute_paths(tmp_path, capsys):
    """The same job in two folders gives the same bytes; a saved trajectory names its character
    relative to itself (or by bundled name), and `report` finds it from anywhere."""
    import shutil

    import numpy as np

    from physmocap.resources import mjcf_dir

    outs = []
    for d in ("one", "two"):
        (tmp_path / d).mkdir()
        out = tmp_path / d / "walk.npz"
        assert main(["retarget", "example", "-o", str(out), "--end", "30", "--quiet"]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] and str(tmp_path).encode() not in outs[0]
    chars = tmp_path / "chars"
    chars.mkdir()
    for name in ("robot.xml", "robot.map.toml"):
        shutil.copy(mjcf_dir() / name, chars / name)
    out = tmp_path / "one" / "robot.npz"
    assert main(["retarget", "example", "-o", str(out), "--character", str(chars / "robot.xml"), "--end", "30", "--quiet"]) == 0
    with np.load(out, allow_pickle=False) as z:
        assert str(z["mjcf_path"]) == "../chars/robot.xml" and str(z["source"]) == "example"
    capsys.readouterr()
    assert main(["report", str(out)]) == 0
    assert "not available" not in capsys.readouterr().err  # "example" is the bundled clip


def test_report_finds_the_stored_source_from_any_folder(tmp_path, capsys, monkeypatch):
    """The trajectory names its source relative to itself; `report` run from another folder
    finds it there (it used to look in the working directory and report without the source)."""
    import json

    (tmp_path / "clips").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "clips" / "walk.bvh").write_bytes(resolve_input("example").read_bytes())
    out = tmp_path / "out" / "w.npz"
    assert main(["retarget", str(tmp_path / "clips" / "walk.bvh"), "-o", str(out), "--end", "12", "--quiet"]) == 0
    monkeypatch.chdir(tmp_path)  # the stored "../clips/walk.bvh" is not a path from here
    capsys.readouterr()
    assert main(["report", "out/w.npz", "--json", "r.json"]) == 0
    assert "not available" not in capsys.readouterr().err
    assert json.loads((tmp_path / "r.json").read_text())["source"] is not None


# --- part 2: structure, sizes and types of every input ------------------------------------
def _npy(arr) -> bytes:
    import io

    import numpy as np

    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def _npy_header(shape) -> bytes:
    import io

    from numpy.lib import format as npformat

    buf = io.BytesIO()
    npformat.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    return buf.getvalue()


@pytest.fixture(scope="module")
def minimal_trajectory():
    """The arrays of a tiny valid trajectory NPZ of the bundled humanoid (3 frames standing)."""
    import numpy as np

    from physmocap.models import load_character

    nq = load_character("humanoid").model.nq
    qpos = np.zeros((3, nq))
    qpos[:, 2], qpos[:, 3] = 1.0, 1.0
    return {"qpos": qpos, "fps": np.array(30.0), "mjcf_path": np.array("humanoid"), "source": np.array("example")}


@pytest.mark.parametrize("command", ["inspect", "report"])
def test_npz_bombs_are_refused_from_the_zip_directory(tmp_path, capsys, monkeypatch, command):
    """Every NPZ reader checks the members' uncompressed sizes before unpacking, and that each
    array's header declares exactly the bytes its member holds."""
    import zipfile

    import physmocap.fileio as fileio

    monkeypatch.setattr(fileio, "MAX_NPZ_BYTES", 1 << 20)  # 1 MB: the bomb below unpacks to 2 MB
    key = "positions" if command == "inspect" else "qpos"
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr(f"{key}.npy", _npy_header(((2 << 20) // 72, 3, 3)) + bytes(((2 << 20) // 72) * 72))
    assert bomb.stat().st_size < 20000
    assert main([command, str(bomb)]) == 2
    line = _one_line(capsys)
    assert "bomb.npz" in line and "would unpack to 2 MB" in line
    liar = tmp_path / "liar.npz"  # a header declaring 10^12 frames over 72 stored bytes
    with zipfile.ZipFile(liar, "w") as z:
        z.writestr(f"{key}.npy", _npy_header((10**12, 3, 3)) + bytes(72))
    assert main([command, str(liar)]) == 2
    line = _one_line(capsys)
    assert "liar.npz" in line and f"array '{key}'" in line and "declares shape" in line


@pytest.mark.parametrize(
    "field, value, needle",
    [
        ("fps", "thirty", "'fps' must be a number"),
        ("fps", 1e308, "'fps' is 1e+308"),
        ("source_start", -5, "'source_start' is -5"),
        ("source_start", "x", "'source_start' must be an integer"),
        ("target_names", "abc", "'target_names' must be a 1-D array of strings"),
        ("target_names", [b"\xff\xfe"], "'target_names'[0] is not UTF-8"),
        ("mjcf_path", b"\xff.xml", "'mjcf_path'[0] is not UTF-8"),
        ("qpos", [["a"]], "'qpos' must be a (frames, nq) array of numbers"),
        ("qpos", "far", "beyond 1000"),
        ("plain", None, "a single .npy array"),
    ],
)
def test_trajectory_npz_fields_are_checked(tmp_path, capsys, minimal_trajectory, field, value, needle):
    import numpy as np

    data = dict(minimal_trajectory)
    path = tmp_path / "traj.npz"
    if field == "plain":
        path.write_bytes(_npy(data["qpos"]))
    else:
        if value == "far":
            value = data["qpos"] + 1e300
        data[field] = np.array(value)
        if field == "target_names":  # with the other target arrays, so only the names are wrong
            data.update(target_positions=np.zeros((3, 1, 3)), target_orientations=np.zeros((3, 1, 4)),
                        target_has_orientation=np.zeros(1, bool), target_valid=np.ones((3, 1), bool))
        np.savez(path, **data)
    assert main(["report", str(path), "--no-source"]) == 2
    line = _one_line(capsys)
    assert "traj.npz" in line and needle in line, line


def test_minimal_trajectory_is_accepted(tmp_path, capsys, minimal_trajectory):
    import numpy as np

    path = tmp_path / "traj.npz"
    np.savez(path, **minimal_trajectory)
    assert main(["report", str(path), "--no-source"]) == 0


@pytest.fixture(scope="module")
def small_mcap(tmp_path_factory):
    path = tmp_path_factory.mktemp("mcap") / "walk.mcap"
    assert main(["convert", "example", str(path), "--end", "10"]) == 0
    return path


def _rewrite_mcap(src, dst, meta_fn=None, msg_fn=None):
    """Copy an MCAP, changing its skeleton metadata and / or its transform messages."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as fh, open(dst, "wb") as out:
        reader = make_reader(fh)
        w = Writer(out)
        w.start()
        schemas, chans = {}, {}
        for s, c, m in reader.iter_messages():
            if s.id not in schemas:
                schemas[s.id] = w.register_schema(s.name, s.encoding, s.data)
            if c.id not in chans:
                chans[c.id] = w.register_channel(c.topic, c.message_encoding, schemas[s.id], c.metadata)
            data = msg_fn(m.data) if msg_fn and c.topic.endswith("/tf") else m.data
            w.add_message(chans[c.id], m.log_time, data, m.publish_time)
        for md in reader.iter_metadata():
            meta = dict(md.metadata)
            if meta_fn:
                meta_fn(meta)
            w.add_metadata(md.name, meta)
        w.finish()


DEEP = "[" * 100000 + "]" * 100000
BIG = "9" * 400


@pytest.mark.parametrize(
    "key, value, needle",
    [
        ("parents", '"abc"', "'parents' must be a list of 38 integers"),
        ("parents", "[-1" + ", 99" * 37 + "]", "'parents' item 1 is 99"),
        ("parents", "[-1" + f", {BIG}" * 37 + "]", "'parents' item 1 must be an integer"),
        ("joints", "5", "'joints' must be a list of strings"),
        ("joints", DEEP, "'joints' is not valid JSON (lists or objects nested too deeply)"),
        ("offsets", '"x"', "'offsets' must be a list of 38 [x, y, z]"),
        ("offsets", f"[[{BIG}, 0, 0]]", "'offsets' must be a list of 38"),
        ("translated", "[500]", "'translated' must list joint indices"),
        ("translated", '"a"', "'translated' must be a list of integers"),
        ("num_frames", "1000000", "'num_frames' is 1e+06; expected an integer from 1 to 50"),
        ("num_frames", BIG, "'num_frames' must be an integer"),
        ("start_time_ns", BIG, "'start_time_ns' must be an integer"),
        ("fps", "1e308", "'fps' is 1e+308"),
        ("source_unit_scale", "1e400", "'source_unit_scale' is inf"),
        ("meta", DEEP, "'meta' is not valid JSON (lists or objects nested too deeply)"),
        ("meta", "[" * 100 + "]" * 100, "must be a JSON object"),
        ("meta", "{\"a\": " + "[" * 100 + "]" * 100 + "}", "'meta' is nested deeper than 64 levels"),
        ("meta", "[1, 2]", "'meta' must be a JSON object"),
        ("meta", '{"floor_z": "x"}', "'meta' entry 'floor_z' has the wrong type"),
        ("meta", '{"format": 5}', "'meta' entry 'format' has the wrong type"),
    ],
)
def test_mcap_skeleton_metadata_is_checked(tmp_path, capsys, small_mcap, key, value, needle):
    bad = tmp_path / "bad.mcap"
    _rewrite_mcap(small_mcap, bad, meta_fn=lambda m: m.__setitem__(key, value))
    assert main(["inspect", str(bad)]) == 2
    line = _one_line(capsys)
    assert "bad.mcap" in line and "skeleton /skeleton" in line and needle in line, line


@pytest.mark.parametrize(
    "old, new, needle",
    [
        (b'"w":1.0', b'"w":1e308', "'rotation' is not a rotation (quaternion norm inf)"),
        (b'"w":1.0', b'"w":' + BIG.encode(), "field 'w' must be a finite number, got inf"),
        (b'"sec":0', b'"sec":1e20', "timestamp sec and nsec must be non-negative integers"),
        (b'"sec":0', b'"sec":100000000000000000000', "timestamp sec and nsec must be non-negative integers"),
        (b'"sec":0', b'"sec":4611686019', "timestamp 4.61169e+09 s is out of range"),
        (b'"transforms":[', b'"x":' + DEEP.encode() + b',"transforms":[', "invalid JSON (lists or objects nested too deeply"),
    ],
)
def test_mcap_messages_are_checked(tmp_path, capsys, small_mcap, old, new, needle):
    bad = tmp_path / "bad.mcap"
    _rewrite_mcap(small_mcap, bad, msg_fn=lambda d: d.replace(old, new, 1))
    assert main(["inspect", str(bad)]) == 2
    line = _one_line(capsys)
    assert "bad.mcap" in line and "message 0 on /skeleton/tf" in line and needle in line, line


@pytest.mark.parametrize("shape, needle", [("deep", "nested more than 100 levels"), ("wide", "more than 1000 joints")])
def test_huge_bvh_hierarchies_are_refused_quickly(tmp_path, capsys, shape, needle):
    """A 20,000-deep chain (or 20,000 siblings) is refused at the joint that passes the limit."""
    import time

    n = 20000
    lines = ["HIERARCHY", "ROOT Hips", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    if shape == "deep":
        for i in range(n):
            lines += [f"JOINT J{i}", "{", "OFFSET 0 0.001 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
        lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * n
    else:
        for i in range(n):
            lines += [f"JOINT J{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation", "}"]
    lines += ["}", "MOTION", "Frames: 1", "Frame Time: 0.033", " ".join(["0"] * (6 + 3 * n))]
    path = tmp_path / "huge.bvh"
    path.write_text("\n".join(lines) + "\n")
    t0 = time.perf_counter()
    assert main(["convert", str(path), str(tmp_path / "out.bvh")]) == 2
    assert time.perf_counter() - t0 < 5
    line = _one_line(capsys)
    assert "huge.bvh:" in line and needle in line, line
    assert not (tmp_path / "out.bvh").exists()


def _jsonl_frame(t=None, names=("head", "left_hip", "right_hip")) -> str:
    import json

    frame = {"joints": {n: [0.1 * i, 0.0, 1.0] for i, n in enumerate(names)}}
    if t is not None:
        frame["time"] = t
    return json.dumps(frame)


@pytest.mark.parametrize(
    "text, needle",
    [
        ('{"fps": 30, "x": ' + "[" * 100000 + "]" * 100000 + "}\n" + _jsonl_frame(), ":1: invalid JSON (lists or objects nested too deeply)"),
        ('{"fps": 30, "joint_names": 5}\n' + _jsonl_frame(), "'joint_names' must be a list of names"),
        (_jsonl_frame(0) + "\n" + _jsonl_frame(0).replace('"time": 0', '"time": ' + "9" * 400),
         ":2: 'time' must be a finite number of seconds"),
        ('{"fps": 30}\n' + _jsonl_frame(0) + "\n" + _jsonl_frame(1e20), "times do not fit"),
        (_jsonl_frame(0) + "\n" + _jsonl_frame(1e-300), "median spacing gives 1e+300 fps"),
        ('{"fps": 30}\n' + "\n".join(_jsonl_frame(names=[f"j{i}_{k}" for k in range(4)]) for i in range(225)),
         "900 samples would be spread over 225 frames x 900 joints"),
        ('{"fps": 30}\n' + _jsonl_frame(names=[f"j{k}" for k in range(1001)]), "1001 joints; physmocap reads at most 1000"),
    ],
)
def test_jsonl_structure_and_numbers_are_checked(tmp_path, capsys, text, needle):
    path = tmp_path / "bad.jsonl"
    path.write_text(text)
    assert main(["inspect", str(path)]) == 2
    line = _one_line(capsys)
    assert "bad.jsonl" in line and needle in line, line


def _robot_map() -> str:
    from physmocap.resources import mjcf_dir

    return (mjcf_dir() / "robot.map.toml").read_text()


@pytest.mark.parametrize(
    "edit, needle",
    [
        (("left = [\"l_heel\", \"l_toe\"]", "left = [" + ", ".join(['"l_heel"'] * 1000) + "]"),
         "[contacts] left: site 'l_heel' is listed more than once"),
        (("right = [\"r_heel\", \"r_toe\"]", "right = [\"l_heel\", \"r_toe\"]"),
         "[contacts] right: site 'l_heel' is already a contact of the left foot"),
        (("left_toe = \"site:l_ball_site\"", "left_toe = \"site:l_ankle_site\""),
         "[joints] left_toe: 'site:l_ankle_site' is already the frame of left_ankle"),
        (("pelvis = \"body:base_link\"", "pelvis = \"body:base_link\"\n\"pelvis\" = \"body:base_link\""),
         "overwrite a value"),
        (("[rest]", "[sites]\nx = " + "[" * 100000 + "]" * 100000 + "\n[rest]"), "nested deeper than 64 levels"),
        (("[rest]", "# " + "x" * (2 << 20) + "\n[rest]"), "larger than 1024 KB"),
        (("name = \"robot\"", "name = \"rob\udcffot\""), ":5: not UTF-8 text (byte 0xff)"),
        (("default = 860", "default = " + "9" * 400), "[velocity_limits] default: expected a finite number, got inf"),
    ],
)
def test_character_mapping_files_are_bounded_and_without_duplicates(tmp_path, capsys, edit, needle):
    text = _robot_map()
    assert edit[0] in text
    path = tmp_path / "bad.map.toml"
    path.write_bytes(text.replace(*edit).encode("utf-8", "surrogateescape"))
    assert main(["character", "info", "robot", "--map", str(path)]) == 2
    line = _one_line(capsys)
    assert "bad.map.toml" in line and needle in line, line


def test_mapping_from_dev_zero_is_refused(capsys):
    assert main(["inspect", "example", "--map", "/dev/zero"]) == 2
    assert "/dev/zero: mapping file is larger than 1024 KB" in _one_line(capsys)


def test_source_mapping_lists_without_duplicates(tmp_path, capsys):
    path = tmp_path / "src.map.toml"
    path.write_text('[joints]\nneck = ["Neck", "Neck1", "Neck"]\n')
    assert main(["inspect", "example", "--map", str(path)]) == 2
    assert "src.map.toml:2: entry 'neck' lists 'Neck' more than once" in _one_line(capsys)


@pytest.mark.parametrize("command", ["replay", "retarget", "clean"])
def test_empty_clip_is_refused_by_commands_that_process_motion(tmp_path, capsys, command):
    path = tmp_path / "empty.bvh"
    path.write_text(BVH.replace("FT", "0.033").split("Frames:")[0] + "Frames: 0\nFrame Time: 0.033\n")
    argv = [command, str(path)] + ([] if command == "replay" else ["-o", str(tmp_path / "out.bvh")])
    assert main(argv) == 2
    assert "empty.bvh: the clip has 0 frames" in _one_line(capsys)
    assert not (tmp_path / "out.bvh").exists()


@pytest.mark.parametrize(
    "old, new, needle",
    [
        (b'name="lumbar_flexion"', b'name="lumbar_\xffflexion"', "the name b'lumbar_\\xffflexion' is not UTF-8 text"),
        (b'<body name="lumbar" pos="0 0 0.121719"', b'<body name="lumbar" pos="1e308 0 0"',
         "body 'lumbar' is not at a finite place within 1 km"),
    ],
)
def test_mjcf_names_and_places_are_checked(tmp_path, capsys, old, new, needle):
    import shutil

    from physmocap.resources import mjcf_dir

    xml = (mjcf_dir() / "humanoid.xml").read_bytes()
    assert old in xml
    (tmp_path / "odd.xml").write_bytes(xml.replace(old, new, 1))
    shutil.copy(mjcf_dir() / "humanoid.map.toml", tmp_path / "odd.map.toml")
    assert main(["character", "info", str(tmp_path / "odd.xml")]) == 2
    line = _one_line(capsys)
    assert "odd.xml" in line and needle in line, line


def test_mcap_outputs_carry_no_absolute_paths(tmp_path):
    """The same job in two folders gives the same MCAP bytes: the source is named relative to it."""
    outs = []
    for d in ("one", "two"):
        (tmp_path / d / "in").mkdir(parents=True)
        (tmp_path / d / "in" / "walk.bvh").write_bytes(resolve_input("example").read_bytes())
        out = tmp_path / d / "walk.mcap"
        assert main(["convert", str(tmp_path / d / "in" / "walk.bvh"), str(out), "--end", "5"]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] and str(tmp_path).encode() not in outs[0]


@pytest.mark.parametrize("every", [False, True])
def test_far_tracker_samples_are_refused_before_any_fit(tmp_path, capsys, every):
    """The positional pipeline checks positions (in metres) before fitting the ground to them
    (a clip of 1e308 everywhere used to break the ground plane's SVD)."""
    rows = ["time,head_x,head_y,head_z,left_hip_x,left_hip_y,left_hip_z,right_hip_x,right_hip_y,right_hip_z"]
    rows += [f"{f / 30},0,0,1.7,0,0.1,1,0,-0.1,1" for f in range(10)]
    if every:
        rows[1:] = [r.split(",")[0] + ",1e308" * 9 for r in rows[1:]]
    else:
        rows[4] = rows[4].replace(",0,0,1.7,", ",0,1e308,1.7,")
    path = tmp_path / "far.npz"
    import numpy as np

    table = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
    np.savez(path, positions=table[:, 1:].reshape(10, 3, 3), names=np.array(["head", "left_hip", "right_hip"]),
             times=table[:, 0], units=np.array("m"))
    assert main(["inspect", str(path)]) == 2
    line = _one_line(capsys)
    assert "far.npz: frame" in line and "is not a finite distance within 1 km" in line, line


# --- part 3: rough edges a new user hit ----------------------------------------------------
def _bad_outputs(tmp_path):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    return blocker


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["retarget", "IN", "-o", "{t}/o.bvh", "--plots", "/proc/nope"], "the plot directory cannot be created"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--plots", "{t}/afile/sub"], "'{t}/afile' is a file"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--plots", "{t}/afile"], "is a file; the plot directory"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--plots", "{t}/nodir/sub"], "'{t}/nodir' does not exist"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--report", "{t}/afile/r.json"], "'{t}/afile' is a file"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--report", "/proc/r.json"], "the report cannot be created"),
        (["retarget", "IN", "-o", "{t}/afile/o.bvh"], "'{t}/afile' is a file"),
        (["retarget", "IN", "-o", "/proc/o.bvh"], "the output file cannot be created"),
        (["retarget", "IN", "-o", "{t}"], "is a directory"),
        (["retarget", "IN", "-o", "{t}/o.bvh", "--qpos", "{t}/afile/q.npz"], "'{t}/afile' is a file"),
        (["clean", "IN", "--plots", "{t}/afile/sub"], "'{t}/afile' is a file"),
        (["clean", "IN", "--plots", "/proc/nope"], "the plot directory cannot be created"),
        (["clean", "IN", "-o", "{t}/afile/c.bvh"], "'{t}/afile' is a file"),
        (["report", "IN", "--plots", "{t}/afile/sub"], "'{t}/afile' is a file"),
        (["report", "IN", "--json", "/proc/r.json"], "the report cannot be created"),
        (["convert", "IN", "{t}/afile/c.bvh"], "'{t}/afile' is a file"),
        (["replay", "IN", "-o", "{t}/afile/c.bvh"], "'{t}/afile' is a file"),
        (["preview", "IN", "-o", "{t}/afile/p.png"], "'{t}/afile' is a file"),
    ],
)
def test_output_paths_are_checked_before_the_input_is_read(tmp_path, capsys, argv, needle):
    """Every output path is checked before any work: the input does not even exist here, and
    the error is about the output (what is wrong with it), not the input."""
    pytest.importorskip("matplotlib")
    _bad_outputs(tmp_path)
    t = str(tmp_path)
    missing = str(tmp_path / ("missing.npz" if argv[0] == "report" else "missing.bvh"))
    argv = [missing if a == "IN" else a.format(t=t) for a in argv]
    assert main(argv) == 2
    line = _one_line(capsys)
    assert needle.format(t=t) in line and "missing" not in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # nothing made, no probe left


@pytest.mark.parametrize("command", ["inspect", "convert", "retarget", "clean", "replay", "preview"])
def test_a_directory_as_input_says_so(tmp_path, capsys, command):
    d = tmp_path / "takes"
    d.mkdir()
    argv = [command, str(d)] + ([str(tmp_path / "o.bvh")] if command == "convert" else [])
    argv += ["-o", str(tmp_path / ("o.png" if command == "preview" else "o.bvh"))] if command not in ("inspect", "convert") else []
    assert main(argv) == 2
    line = _one_line(capsys)
    assert "takes: is a directory" in line and "(none)" not in line, line


def _help(capsys, *argv) -> str:
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_help_agrees_with_the_readers_and_writers(capsys):
    """Help texts list what the code accepts: every format retarget and convert write,
    every unit --in-units takes (for the BVH and the tracker readers alike)."""
    from physmocap.cli.retarget import WRITERS
    from physmocap.export import MOTION_WRITERS
    from physmocap.sources.bvh import UNIT_SCALES as BVH_UNITS
    from physmocap.sources.sensor import UNIT_SCALES as SENSOR_UNITS

    top = _help(capsys)
    retarget_line = top[top.index("retarget retarget"):top.index("report measure")]
    for suffix in WRITERS:
        assert suffix[1:].upper() in retarget_line, retarget_line
    conv = _help(capsys, "convert")
    out_help = conv[conv.index("OUT output"):conv.index("options:")]
    for suffix in MOTION_WRITERS:
        assert suffix in out_help, out_help
    assert set(BVH_UNITS) == set(SENSOR_UNITS)
    for command in ("retarget", "convert", "inspect", "report"):
        text = _help(capsys, command)
        units_help = text[text.index("--in-units"):]
        units_help = units_help[: units_help.index("default: detect")]
        for unit in BVH_UNITS:
            assert f" {unit}," in units_help or f" {unit} " in units_help, (command, unit, units_help)


@pytest.mark.parametrize("unit,scale", [("dm", 0.1), ("ft", 0.3048), ("feet", 0.3048), ("mm", 0.001)])
def test_tracker_files_take_every_unit_of_the_help(unit, scale):
    from physmocap.sources.sensor import unit_scale

    assert unit_scale(unit)[1] == scale


def test_plot_hints_quote_the_extra(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    from physmocap.errors import OptionError
    from physmocap.plots import require_matplotlib

    with pytest.raises(OptionError, match=r"pip install 'physmocap\[plot\]'"):
        require_matplotlib()
    for command in ("retarget", "report", "clean"):
        text = _help(capsys, command)
        assert "pip install 'physmocap[plot]'" in text, command


def test_inspect_and_convert_count_joints_alike(tmp_path, capsys):
    assert main(["inspect", "example"]) == 0
    inspected = capsys.readouterr().out
    assert "skeleton:  31 joints, 7 end sites" in inspected
    assert main(["convert", "example", str(tmp_path / "c.bvh"), "--end", "2"]) == 0
    assert "31 joints and 7 end sites" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["retarget", "convert", "preview"])
def test_an_empty_frame_range_is_called_empty(tmp_path, capsys, command):
    out = str(tmp_path / ("o.png" if command == "preview" else "o.bvh"))
    argv = [command, "example", out] if command == "convert" else [command, "example", "-o", out]
    assert main([*argv, "--start", "10", "--end", "5"]) == 2
    line = _one_line(capsys)
    assert "--start 10 --end 5: the range is empty" in line, line


def test_inspect_json_states_the_axes_of_its_offsets(capsys):
    import json

    assert main(["inspect", "example", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["file_up"] == "Y" and rep["offset_axes"] == "Z-up"
    assert "Z-up" in rep["offset_note"] and "Y-up" in rep["offset_note"]


def test_report_finds_a_bundled_character_by_name_or_by_an_old_path(tmp_path, capsys, minimal_trajectory):
    """`report` needs no --character when the file names a bundled character, by name or by the
    absolute path another machine (an older physmocap) stored."""
    import numpy as np

    for stored in ("humanoid", "/some/other/machine/physmocap/assets/mjcf/humanoid.xml"):
        path = tmp_path / "t.npz"
        np.savez(path, **{**minimal_trajectory, "mjcf_path": np.array(stored)})
        with warnings_caught(stored.startswith("/")):
            assert main(["report", str(path), "--no-source"]) == 0, capsys.readouterr().err
        out = capsys.readouterr()
        assert "--character" not in out.err and "humanoid" in out.out
    np.savez(path, **{**minimal_trajectory, "mjcf_path": np.array("/elsewhere/mine.xml")})
    assert main(["report", str(path), "--no-source"]) == 2
    assert "pass --character" in _one_line(capsys)


def warnings_caught(expected: bool):
    import contextlib

    from physmocap.errors import PhysmocapWarning

    return pytest.warns(PhysmocapWarning, match="using the bundled 'humanoid'") if expected else contextlib.nullcontext()


def test_quiet_prints_no_report_table(tmp_path, capsys):
    out, report = tmp_path / "o.bvh", tmp_path / "r.json"
    argv = ["retarget", "example", "-o", str(out), "--report", str(report), "--start", "1", "--end", "12"]
    assert main([*argv, "--quiet"]) == 0
    quiet = capsys.readouterr()
    assert quiet.out == "" and "wrote" not in quiet.err and report.exists()
    assert main(argv) == 0
    loud = capsys.readouterr()
    assert "Foot skating" in loud.out and f"wrote {out}" in loud.err


# --- all the outputs of one run, or none --------------------------------------------------
def test_output_set_renames_together_or_not_at_all(tmp_path, capsys):
    from physmocap.errors import OutputError
    from physmocap.fileio import OutputSet, announce, atomic_open, make_output_dir

    old = tmp_path / "a.txt"
    old.write_text("old")
    with pytest.raises(OutputError, match="b.txt: not written: disk full"):
        with OutputSet():
            with atomic_open(old) as fh:
                fh.write("new")
            make_output_dir(tmp_path / "plots")
            with atomic_open(tmp_path / "plots" / "p.txt") as fh:
                fh.write("p")
            announce("wrote a.txt")
            assert old.read_text() == "old" and not (tmp_path / "plots" / "p.txt").exists()  # not yet
            with atomic_open(tmp_path / "b.txt") as fh:
                fh.write("half")
                raise OSError(28, "disk full")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"] and old.read_text() == "old"
    assert "wrote" not in capsys.readouterr().err
    with OutputSet() as outer:
        with OutputSet():  # an inner set (a writer of two files) hands its files to the outer one
            with atomic_open(tmp_path / "b.txt") as fh:
                fh.write("b")
        assert outer.pending == [tmp_path / "b.txt"] and not (tmp_path / "b.txt").exists()
        with atomic_open(old) as fh:
            fh.write("new")
        announce("wrote both")
    assert old.read_text() == "new" and (tmp_path / "b.txt").read_text() == "b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
    assert capsys.readouterr().err == "wrote both\n"


def _fail_last(monkeypatch, module, name):
    """Make ``module.name`` (the run's last writer) write half its file, then fail as a full disk."""
    from physmocap.fileio import atomic_open

    def boom(*args, **kwargs):
        path = next(a for a in args if isinstance(a, (str, __import__("os").PathLike)))
        with atomic_open(path) as fh:
            fh.write("{")
            raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(module, name, boom)


def test_retarget_failing_in_its_last_output_leaves_none(tmp_path, capsys, monkeypatch):
    import physmocap.report

    names = ["a.bvh", "a.npz", "a.csv", "r.json"]
    outs = [str(tmp_path / n) for n in names]
    argv = ["retarget", "example", "-o", outs[0], "--qpos", outs[1], "--csv", outs[2], "--report", outs[3],
            "--start", "1", "--end", "12", "--quiet"]
    _fail_last(monkeypatch, physmocap.report, "write_report_json")
    assert main(argv) == 2
    assert "No space left on device" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []  # none of the new files, no temporary file
    for n in names:  # an earlier run's files stay as they were
        (tmp_path / n).write_text("old")
    assert main(argv) == 2
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    assert all((tmp_path / n).read_text() == "old" for n in names)
    monkeypatch.undo()
    assert main(argv) == 0
    assert all((tmp_path / n).read_bytes() != b"old" for n in names)


def test_retarget_with_plots_failing_removes_the_plot_directory_it_made(tmp_path, capsys, monkeypatch):
    pytest.importorskip("matplotlib")
    import physmocap.plots

    real = physmocap.plots._joints_plot

    def boom(*args):
        real(*args)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(physmocap.plots, "_joints_plot", boom)
    argv = ["retarget", "example", "-o", str(tmp_path / "a.npz"), "--plots", str(tmp_path / "plots"),
            "--start", "1", "--end", "12", "--quiet"]
    assert main(argv) == 2
    capsys.readouterr()
    assert list(tmp_path.iterdir()) == []


def test_clean_failing_in_its_report_leaves_no_bvh(tmp_path, capsys, monkeypatch):
    import physmocap.cli.clean as clean_cli

    def boom(obj, fh, **kwargs):
        fh.write("{")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(clean_cli.json, "dump", boom)
    out = tmp_path / "c.bvh"
    assert main(["clean", "example", "-o", str(out), "--report", str(tmp_path / "g.json")]) == 2
    assert "No space left on device" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_robot_csv_and_its_joint_names_are_one_output(tmp_path, capsys, monkeypatch):
    import physmocap.export.robot as robot

    real = robot.atomic_open
    calls = []

    def second_fails(path, *a, **k):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(path, *a, **k)

    monkeypatch.setattr(robot, "atomic_open", second_fails)
    out = tmp_path / "r.csv"
    assert main(["retarget", "example", "-o", str(out), "--format", "robot-csv", "--start", "1", "--end", "6",
                 "--quiet"]) == 2
    capsys.readouterr()
    assert list(tmp_path.iterdir()) == []


def test_the_same_path_twice_is_refused(tmp_path, capsys):
    out = str(tmp_path / "a.npz")
    assert main(["retarget", "example", "-o", out, "--qpos", out]) == 2
    assert "given twice as an output" in _one_line(capsys)


def test_an_error_without_a_file_names_the_commands_input(tmp_path, capsys):
    """Issue 15: clean errors that did not name the file, e.g. a skeleton whose hips coincide."""
    import re

    from physmocap.resources import resolve_input

    text = resolve_input("example").read_text()

    def offset(name: str) -> re.Match:
        return re.search(r"JOINT %s\s*\{\s*OFFSET ([^\n]+)" % name, text)

    for left, right in (("LHipJoint", "RHipJoint"), ("LeftUpLeg", "RightUpLeg")):
        a, b = offset(left), offset(right)
        text = text[: b.start(1)] + a.group(1) + text[b.end(1) :]
    src = tmp_path / "hips.bvh"
    src.write_text(text)
    assert main(["retarget", str(src), "-o", str(tmp_path / "out.bvh")]) == 2
    line = _one_line(capsys)
    assert f"{src}: cannot tell which way the skeleton faces" in line, line


# --- an output path must name a file -----------------------------------------------------
@pytest.mark.parametrize("argv", [
    ["retarget", "example", "-o", "{d}/adir.bvh/"],
    ["retarget", "example", "-o", "{d}/o.bvh", "--qpos", "{d}/q.npz/"],
    ["retarget", "example", "-o", "{d}/o.bvh", "--csv", "{d}/q.csv/"],
    ["retarget", "example", "-o", "{d}/o.bvh", "--report", "{d}/r.json/"],
    ["retarget", "example", "-o", "{d}/o.bvh", "--preview", "{d}/p.gif/"],
    ["convert", "example", "{d}/adir.bvh/"],
    ["clean", "example", "-o", "{d}/adir.bvh/"],
    ["preview", "example", "-o", "{d}/adir.mp4/"],
    ["replay", "example", "-o", "{d}/r.npz/"],
    ["replay", "example", "--stats", "{d}/s.json/"],
    ["character", "scale", "-o", "{d}/s.xml/", "--height", "1.6"],
    ["character", "init", "robot", "-o", "{d}/m.toml/"],
])
def test_an_output_ending_with_a_separator_is_refused(tmp_path, capsys, argv):
    """``-o adir.bvh/`` names a directory: refused before any work, not written as a file
    ``adir.bvh`` (``Path`` drops the trailing separator)."""
    args = [a.format(d=tmp_path) for a in argv]
    assert main(args) == 2
    line = _one_line(capsys)
    bad = next(a for a in args if a.endswith("/"))
    assert line.startswith(f"physmocap: error: {bad}: ends with a path separator"), line
    assert list(tmp_path.iterdir()) == []


def test_an_output_naming_a_directory_or_a_device_is_refused(tmp_path, capsys):
    (tmp_path / "d.bvh").mkdir()
    assert main(["retarget", "example", "-o", str(tmp_path / "d.bvh")]) == 2
    assert "d.bvh: is a directory" in _one_line(capsys)
    fifo = tmp_path / "p.json"
    os.mkfifo(fifo)  # a device or pipe would be replaced by the renamed file: refused
    assert main(["retarget", "example", "-o", str(tmp_path / "o.bvh"), "--report", str(fifo)]) == 2
    assert "p.json: is not a regular file" in _one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.bvh", "p.json"] and fifo.is_fifo()


def test_a_manifest_output_ending_with_a_separator_is_refused(tmp_path, capsys):
    manifest = tmp_path / "jobs.csv"
    manifest.write_text("input,output\nexample,a.npz/\n")
    assert main(["batch", str(manifest), "-o", str(tmp_path / "out")]) == 2
    assert f"{manifest}:2: output 'a.npz/' ends with a path separator" in _one_line(capsys)


# --- the repository's scripts ------------------------------------------------------------
def test_lowest_deps_help_prints_usage_and_touches_nothing(tmp_path):
    from conftest import REPO

    venv = tmp_path / "venv"
    venv.mkdir()
    (venv / "keep").write_text("x")
    for flag in ("-h", "--help"):
        r = subprocess.run(["bash", str(REPO / "scripts" / "lowest_deps.sh"), flag], capture_output=True, text=True,
                           timeout=60, env={**os.environ, "LOWEST_VENV": str(venv), "PYTHON": "false"})
        assert r.returncode == 0 and "lowest_deps.sh tests/" in r.stdout and not r.stderr, r.stderr
        assert (venv / "keep").read_text() == "x"


@pytest.mark.parametrize("script", ["evaluate.py", "fidelity.py"])
def test_scripts_refuse_a_clip_that_is_not_there(tmp_path, script):
    """A named clip not in the data folder stops the script with status 2 before any work
    (it used to print 'skip' and exit 0); a folder holding none of the default clips too."""
    from conftest import REPO

    (tmp_path / "walk.bvh").write_text("")
    env = {**os.environ, "PHYSMOCAP_SHARED_DATA": str(tmp_path)}
    run = [sys.executable, str(REPO / "scripts" / script)]
    r = subprocess.run([*run, "--clips", "walk", "nope"], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2 and r.stderr.strip() == f"{script[:-3]}: error: clip(s) not found in {tmp_path}: nope"
    assert "clip" not in r.stdout
    empty = tmp_path / "empty"
    empty.mkdir()
    r = subprocess.run(run, capture_output=True, text=True, timeout=120,
                       env={**env, "PHYSMOCAP_SHARED_DATA": str(empty)})
    assert r.returncode == 2 and "none of the clips found" in r.stderr


def test_scripts_take_a_clip_without_its_suffix(tmp_path):
    import runpy

    from conftest import REPO

    clips = runpy.run_path(str(REPO / "scripts" / "_clips.py"))
    (tmp_path / "cmu_12_01_walk.bvh").write_text("")
    (tmp_path / "take.trc").write_text("")
    assert clips["resolve_clips"](tmp_path, ["cmu_12_01_walk", "take.trc"], [], "x") == [
        tmp_path / "cmu_12_01_walk.bvh", tmp_path / "take.trc"]
    assert clips["find_clip"](tmp_path, "take") is None


def test_shared_data_skip_names_the_folder_looked_in(tmp_path, monkeypatch):
    import conftest

    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path)
    monkeypatch.setattr(conftest, "SHARED_DATA_ORIGIN", "from PHYSMOCAP_SHARED_DATA")
    with pytest.raises(pytest.skip.Exception) as info:
        conftest.shared_file("nope.bvh")
    reason = str(info.value)
    assert reason.endswith(f"nope.bvh not found in {tmp_path} (from PHYSMOCAP_SHARED_DATA)"), reason
    r = subprocess.run([sys.executable, "-c", "import conftest; print(conftest.SHARED_DATA, conftest.SHARED_DATA_ORIGIN)"],
                       capture_output=True, text=True, timeout=60, cwd=conftest.REPO / "tests",
                       env={**os.environ, "PHYSMOCAP_SHARED_DATA": str(tmp_path)})
    assert r.stdout.strip() == f"{tmp_path} from PHYSMOCAP_SHARED_DATA", r.stderr


def test_a_failed_rename_names_its_output(tmp_path, monkeypatch):
    """An OutputSet whose rename into place fails names that output, not the run's last one."""
    import physmocap.fileio as fileio
    from physmocap.errors import OutputError

    real = os.replace

    def failing(src, dst):
        if str(dst).endswith("a.txt"):
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(src), str(dst))
        return real(src, dst)

    monkeypatch.setattr(fileio.os, "replace", failing)
    with pytest.raises(OutputError) as info:
        with fileio.OutputSet():
            for name in ("a.txt", "b.txt"):
                with fileio.atomic_open(tmp_path / name) as fh:
                    fh.write(name)
    assert str(info.value) == f"{tmp_path / 'a.txt'}: not written: {os.strerror(errno.EIO)}"
    assert list(tmp_path.iterdir()) == []


def test_messages_call_the_bundled_clip_example(tmp_path, capsys):
    """Warnings, errors and the lines the commands print name the bundled clip ``example``, as
    the user gave it, never by its place in this installation."""
    import json

    installed = str(resolve_input("example"))
    assert main(["retarget", "example", "-o", str(tmp_path / "o.bvh"), "--in-units", "furlong"]) == 2
    assert _one_line(capsys).startswith("physmocap: error: example: unknown length unit 'furlong'")
    with pytest.warns(Warning) as caught:
        assert main(["retarget", "example", "-o", str(tmp_path / "o.bvh"), "--end", "12", "--quiet"]) == 0
    assert any(str(w.message).startswith("example: frame 0 looks like a reference pose") for w in caught)
    assert main(["inspect", "example", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["file"] == "example"
    assert main(["convert", "example", str(tmp_path / "c.bvh"), "--end", "5"]) == 0
    assert main(["clean", "example", "--report", str(tmp_path / "g.json")]) == 0
    out = capsys.readouterr()
    assert "physmocap: read example:" in out.err and out.out.startswith("example: ")
    assert json.loads((tmp_path / "g.json").read_text())["source"] == "example"
    assert all(installed not in str(w.message) for w in caught)
    assert installed not in out.out + out.err


def test_library_warnings_point_at_the_callers_line(tmp_path):
    """A warning from a library call is attributed to the caller's line (Python's default format
    shows that line, not physmocap's own ``warn(...)``)."""
    script = tmp_path / "use.py"
    script.write_text("from physmocap.ik.retarget import default_start\n"
                      "from physmocap.sources import load_motion\n"
                      "motion = load_motion('example')\n"
                      "first = default_start(motion)\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith(f"{script}:4: PhysmocapWarning: example: frame 0 looks like a reference pose"), r.stderr
    assert lines[1:] == ["  first = default_start(motion)"], r.stderr
    from physmocap.ik.retarget import default_start
    from physmocap.sources import load_motion

    motion = load_motion("example")
    line = sys._getframe().f_lineno + 2
    with pytest.warns(Warning) as caught:
        default_start(motion)
    assert [(w.filename, w.lineno) for w in caught] == [(__file__, line)]


def test_the_cli_gives_pythons_warning_format_back_when_it_returns(capsys):
    """``physmocap.cli.main`` prints warnings as ``physmocap: warning: ...`` while it runs and
    leaves a calling program's warning format as it found it."""
    import warnings

    from physmocap.cli import main

    before = warnings.formatwarning
    assert main(["character", "info", "humanoid"]) == 0
    assert warnings.formatwarning is before
    with pytest.raises(SystemExit):
        main(["--version"])
    assert warnings.formatwarning is before
