"""`physmocap retarget` from the command line: outputs, and one clear error per bad input."""

from __future__ import annotations

import os
import shutil
import warnings

import numpy as np
import pytest

from physmocap.cli import main
from physmocap.resources import mjcf_dir
from conftest import RETARGET_DIAGNOSTICS

pytestmark = RETARGET_DIAGNOSTICS

TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.033333
0 90 0 0 0 0 0 0 0
0 90 0 0 0 0 0 0 0
"""


def _error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("physmocap: error:")]
    assert len(lines) == 1, err
    return lines[0]


def test_retarget_writes_every_format(tmp_path, capsys):
    out = tmp_path / "w.bvh"
    args = ["retarget", "example", "-o", str(out), "--qpos", str(tmp_path / "w.npz"), "--csv", str(tmp_path / "w.csv")]
    assert main(args + ["--end", "60", "--quiet"]) == 0
    for name in ("w.bvh", "w.npz", "w.csv"):
        assert (tmp_path / name).stat().st_size > 0
    assert main(["retarget", "example", "-o", str(tmp_path / "w.mcap"), "--end", "30", "--quiet"]) == 0
    assert (tmp_path / "w.mcap").read_bytes()[:5] == b"\x89MCAP"


def test_unmappable_skeleton(tmp_path, capsys):
    clip = tmp_path / "tiny.bvh"
    clip.write_text(TINY_BVH)
    out = tmp_path / "out.bvh"
    assert main(["retarget", str(clip), "-o", str(out)]) == 2
    line = _error(capsys)
    assert "tiny.bvh" in line and "knee" in line  # names the missing joints
    assert list(tmp_path.iterdir()) == [clip]


def test_character_without_contacts(tmp_path, capsys):
    src = mjcf_dir()
    for name in os.listdir(src):
        if name.startswith("robot") and (src / name).is_file():
            shutil.copy(src / name, tmp_path / name)
    mapping = (tmp_path / "robot.map.toml").read_text()
    start = mapping.index("[contacts]")
    end = mapping.index("\n[", start + 1) + 1  # the next table header
    (tmp_path / "robot.map.toml").write_text(mapping[:start] + mapping[end:])
    out = tmp_path / "out.bvh"
    # without [contacts] the heel and toe are found on the feet's collision geoms
    from physmocap.models import load_character

    ch = load_character(tmp_path / "robot.xml")
    assert ch.contacts == {"left": ("left_auto_heel", "left_auto_toe"), "right": ("right_auto_heel", "right_auto_toe")}
    heel, toe = (ch.model.site(s).pos for s in ch.contacts["left"])
    assert toe[0] - heel[0] > 0.1  # heel behind toe along the foot
    assert main(["retarget", "example", "-o", str(out), "--character", str(tmp_path / "robot.xml"), "--end", "40"]) == 0
    assert out.exists()


def test_no_plant_needs_no_contacts(tmp_path, capsys):
    """A character whose feet have no geometry to find contacts on still retargets with --no-plant."""
    from physmocap.models import load_character

    src = mjcf_dir()
    for name in os.listdir(src):
        if name.startswith("robot") and (src / name).is_file():
            shutil.copy(src / name, tmp_path / name)
    xml = (tmp_path / "robot.xml").read_text()
    import re

    xml = re.sub(r'<geom name="[lr]_foot_box"[^>]*/>', '<inertial pos="0 0 0" mass="0.6" diaginertia="1e-3 1e-3 1e-3"/>', xml)
    (tmp_path / "robot.xml").write_text(xml)
    mapping = (tmp_path / "robot.map.toml").read_text()
    start = mapping.index("[contacts]")
    (tmp_path / "robot.map.toml").write_text(mapping[:start] + mapping[mapping.index("\n[", start + 1) + 1:])
    out = tmp_path / "out.bvh"
    ch = load_character(tmp_path / "robot.xml")
    if ch.contacts:
        pytest.skip("this model still has geometry below its ankles")
    assert main(["retarget", "example", "-o", str(out), "--character", str(tmp_path / "robot.xml")]) == 2
    assert "--no-plant" in _error(capsys)
    assert main(["retarget", "example", "-o", str(out), "--character", str(tmp_path / "robot.xml"), "--no-plant", "--end", "30"]) == 0


@pytest.mark.parametrize(
    "rng,needle",
    [
        (["--start", "600"], "outside the clip"),
        (["--start", "10", "--end", "5"], "the range is empty"),
        (["--end", "9999"], "outside the clip"),
    ],
)
def test_frame_range_outside_the_clip(tmp_path, capsys, rng, needle):
    out = tmp_path / "out.bvh"
    assert main(["retarget", "example", "-o", str(out), *rng]) == 2
    assert needle in _error(capsys)
    assert not out.exists()


def test_unwritable_output(tmp_path, capsys):
    assert main(["retarget", "example", "-o", str(tmp_path / "missing" / "out.bvh")]) == 2
    assert "does not exist" in _error(capsys)
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    assert main(["retarget", "example", "-o", str(blocker / "out.bvh")]) == 2
    line = _error(capsys)
    assert "a_file" in line
    assert blocker.read_text() == "not a directory"


def test_failure_leaves_no_partial_file_and_keeps_an_old_one(tmp_path, capsys, monkeypatch):
    """A failure while writing leaves the previous file untouched and no temporary file."""
    out = tmp_path / "out.npz"
    out.write_bytes(b"old")
    import physmocap.export.trajectory as tj

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(tj.np.lib.format, "write_array", boom)
    with pytest.raises(RuntimeError):
        main(["retarget", "example", "-o", str(out), "--end", "20", "--quiet"])
    assert out.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.npz"]


def test_npz_loads_without_pickle(tmp_path):
    out = tmp_path / "w.npz"
    assert main(["retarget", "example", "-o", str(out), "--start", "0", "--end", "40", "--quiet"]) == 0
    with np.load(out, allow_pickle=False) as z:
        assert z["qpos"].shape[0] == 40 and np.all(np.isfinite(z["qpos"]))
        assert z["target_positions"].shape[0] == 40


@pytest.mark.parametrize(
    "argv",
    [
        ["retarget", "example", "-o", "x.bvh", "--up", "X"],
        ["retarget"],
        ["convert", "example", "x.bvh", "--fps", "abc"],
        ["nosuch"],
    ],
)
def test_usage_errors_are_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("physmocap: error:") and "--help" in err


def test_fps_is_bounded(tmp_path, capsys):
    assert main(["retarget", "example", "-o", str(tmp_path / "x.bvh"), "--fps", "1e9"]) == 2
    assert "frame rate" in _error(capsys)
    assert list(tmp_path.iterdir()) == []


def test_bvh_output_options_without_a_bvh_output_are_said_to_be_ignored(tmp_path, capsys):
    """Before: ``--units cm`` with ``-o x.npz`` was silently ignored."""
    from physmocap.cli import main

    with pytest.warns(UserWarning, match="--units applies to BVH outputs only"):
        assert main(["retarget", "example", "--start", "1", "--end", "12", "-o", str(tmp_path / "x.npz"), "--units", "cm"]) == 0


def _flipped_walk(tmp_path):
    """The bundled walk's first 1.5 s, and the same with the left thigh flipped 180 degrees
    about the hip's lateral axis on 6 frames (a capture flip: the leg swung up through the
    pelvis and back), both written as BVH."""
    from scipy.spatial.transform import Rotation

    from physmocap.export.bvh import write_bvh
    from physmocap.sources import load_motion

    motion = load_motion("example")
    motion = motion.slice_frames(1, 1 + int(1.5 * motion.fps))
    clean_path, flipped_path = tmp_path / "walk.bvh", tmp_path / "flipped.bvh"
    write_bvh(motion, clean_path)
    j = motion.skeleton.index("LeftUpLeg")
    rot = motion.rotations.copy()
    flip = Rotation.from_rotvec([np.pi, 0.0, 0.0])
    rot[80:86, j] = (flip * Rotation.from_quat(rot[80:86, j])).as_quat()
    write_bvh(motion.replace(rotations=rot), flipped_path)
    return clean_path, flipped_path


def test_clean_repairs_a_flip_in_the_source_before_retargeting(tmp_path):
    """``retarget --clean`` follows the repaired source: the flipped thigh's frames come out
    near the unglitched clip's retarget, where without it the hip swings to follow the flip;
    the repair is named in a warning."""
    clean_path, flipped_path = _flipped_walk(tmp_path)
    outs = {}
    for name, src, extra in (("ref", clean_path, []), ("raw", flipped_path, []), ("fixed", flipped_path, ["--clean"])):
        out = tmp_path / f"{name}.npz"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert main(["retarget", str(src), "-o", str(out), "--quiet", "--start", "0", *extra]) == 0
        outs[name] = np.load(out)["qpos"]
        said = [str(w.message) for w in caught if "--clean" in str(w.message)]
        assert said == ([] if name != "fixed" else [
            f"{flipped_path}: --clean repaired 1 capture glitch(es) before retargeting (flip LeftUpLeg 80-85)"
        ])
    from physmocap.models import load_character

    model = load_character("humanoid").model
    hip = [int(model.joint(n).qposadr[0]) for n in ("left_hip_flexion", "left_hip_adduction", "left_hip_rotation")]
    window = slice(78, 92)
    raw = np.abs(outs["raw"][window][:, hip] - outs["ref"][window][:, hip]).max()
    fixed = np.abs(outs["fixed"][window][:, hip] - outs["ref"][window][:, hip]).max()
    assert raw > np.radians(30.0)  # the glitch reaches the character without --clean
    assert fixed < np.radians(5.0) and fixed < raw / 10


def test_clean_leaves_a_clip_without_glitches_byte_identical(tmp_path, capsys):
    clean_path, _ = _flipped_walk(tmp_path)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["retarget", str(clean_path), "-o", str(a), "--quiet", "--start", "0", "--no-plant"]) == 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["retarget", str(clean_path), "-o", str(b), "--quiet", "--start", "0", "--no-plant", "--clean"]) == 0
    assert not [w for w in caught if "--clean" in str(w.message)]  # a one-stride walk: no knee clamp taken for a freeze
    assert np.array_equal(np.load(a)["qpos"], np.load(b)["qpos"])


@pytest.mark.parametrize("command", ["retarget", "preview", "report", "batch"])
@pytest.mark.parametrize("option,name,needle", [
    ("--contacts", "nope.csv", "contact label file not found"),
    ("--source-map", "nope.toml", "mapping file not found"),
    ("--map", "nope.toml", "mapping file not found"),
    ("--marker-set", "nope.toml", "marker set file not found"),
    ("--character", "nope.xml", "MJCF file not found"),
    ("--map", ".", "is a directory, expected a mapping file"),
])
def test_option_files_are_checked_before_the_input_is_read(tmp_path, capsys, monkeypatch, command, option, name,
                                                           needle):
    """A missing or unusable file named by an option is the one error, before the capture (or
    the saved trajectory) is read and retargeted: no warnings about the input first."""
    import physmocap.report
    import physmocap.sources

    def no_reading(*args, **kwargs):
        raise AssertionError("the input was read before the option files were checked")

    monkeypatch.setattr(physmocap.sources, "load_motion", no_reading)
    monkeypatch.setattr(physmocap.report, "load_trajectory", no_reading)
    value = str(tmp_path / name) if name != "." else str(tmp_path)
    outputs = {"retarget": ["-o", str(tmp_path / "o.bvh")], "preview": ["-o", str(tmp_path / "o.gif")],
               "report": [], "batch": ["-o", str(tmp_path / "out")]}
    inp = str(tmp_path / "walk.npz") if command == "report" else "example"
    assert main([command, inp, *outputs[command], option, value]) == 2
    err = capsys.readouterr().err
    assert err == f"physmocap: error: {value}: {needle}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == []

