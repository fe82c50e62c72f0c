"""Marker files on the command line: units overrides, ``solve --character``, the solved loader."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from conftest import shared_file
from physmocap.cli import main
from physmocap.sources import load_motion
from test_markers import _standing_markers, _write_trc, solve_fails_cleanly


def test_inspect_takes_the_unit_given_for_marker_files(tmp_path, capsys):
    labels, P, _ = _standing_markers(10)
    path = tmp_path / "take.trc"
    _write_trc(path, labels, P * 1000)  # millimetres, as the header says
    assert main(["inspect", str(path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["units"] == "from the file" and abs(rep["marker_height_m"] - 1.67) < 0.01
    assert main(["inspect", str(path), "--json", "--in-units", "cm"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["units"] == "cm" and abs(rep["marker_height_m"] - 16.7) < 0.1
    assert main(["inspect", str(path), "--in-units", "furlong"]) == 2
    err = capsys.readouterr().err
    assert "unknown marker unit 'furlong'" in err and "Traceback" not in err


def test_c3d_unit_override():
    from physmocap.sources.c3d import read_c3d_markers

    path = shared_file("cmu_01_01_markers.c3d")
    a, b = read_c3d_markers(path), read_c3d_markers(path, units="cm")
    assert np.allclose(b.positions, 10 * a.positions, equal_nan=True)


def test_solve_onto_a_character_writes_the_character_and_the_actor(tmp_path):
    path = shared_file("cmu_01_01_markers.c3d")
    out, actor = tmp_path / "robot.npz", tmp_path / "actor.bvh"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["solve", str(path), "--end", "120", "-o", str(out), "--character", "robot",
                     "--actor", str(actor), "--quiet"]) == 0
        assert load_motion(actor).num_frames == 120
    with np.load(out) as z:
        assert z["qpos"].shape[0] == 120 and np.all(np.isfinite(z["qpos"]))


def test_solve_options_are_checked_before_the_solve(tmp_path, capsys):
    path = tmp_path / "take.trc"
    labels, P, _ = _standing_markers(10)
    _write_trc(path, labels, P * 1000)
    assert main(["solve", str(path), "-o", str(tmp_path / "a.npz")]) == 2
    assert "writes a .bvh file" in capsys.readouterr().err
    assert main(["solve", str(path), "-o", str(tmp_path / "a.bvh"), "--actor", str(tmp_path / "b.bvh")]) == 2
    assert "--actor and --map go with --character" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.bvh"))


def test_load_motion_solves_a_marker_file_on_request():
    path = shared_file("cmu_01_01_markers.c3d")
    from physmocap.markers.motion import solved_motion
    from physmocap.markers.recording import MarkerRecording
    from physmocap.sources.c3d import read_c3d_markers

    rec = read_c3d_markers(path)
    rec = MarkerRecording(rec.labels, rec.positions[:120], rec.fps, rec.source)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = solved_motion(rec)
    assert m.is_rotational and m.num_frames == 120 and "left_knee" in m.skeleton.names
    assert m.meta["marker_residual_rms_mm"] < 15.0
    with pytest.raises(Exception, match="do not apply to a solved marker recording"):
        solved_motion(rec, max_gap=3)


def test_single_limb_markers_take_the_side_they_are_on():
    """vicon_upperbody: ISB-style labels without a side (EPICl = lateral epicondyle, not left)
    on the subject's right arm: the arm's roles go to the right side, nothing to the left."""
    from physmocap.markers.functional import segment_markers
    from physmocap.markers.markerset import recording_marker_set
    from physmocap.sources.trc import read_trc_markers

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_trc_markers(shared_file("vicon_upperbody.trc"))
    ms = recording_marker_set(rec)
    lab = {role: rec.labels[i] for role, i in ms.roles.items()}
    assert lab["RELB"] == "EPICl" and lab["RELBM"] == "EPICm" and lab["RWRA"] == "STYLr" and lab["RSHO"] == "ACRO_tip"
    assert not any(r.startswith("L") and r not in ("LASI", "LPSI") for r in ms.roles)
    segs = segment_markers(rec, ms)
    assert not any(s.startswith("left_") for s in segs.values())
    assert segs[rec.labels.index("ARMl")] == "right_upper_arm"


@pytest.mark.parametrize("command", ["solve", "convert"])
@pytest.mark.parametrize("frames", [["--start", "10"], ["--start", "4", "--end", "11"], ["--end", "40"]])
def test_a_frame_range_outside_the_markers_is_one_error_and_no_file(tmp_path, capsys, command, frames):
    path = tmp_path / "take.trc"
    labels, P, _ = _standing_markers(10)
    _write_trc(path, labels, P * 1000)
    out = tmp_path / ("a.bvh" if command == "solve" else "a.mcap")
    args = [command, str(path), "-o", str(out)] if command == "solve" else [command, str(path), str(out)]
    assert main(args + frames) == 2
    err = capsys.readouterr().err
    assert f"{path}: frame range" in err and "not inside the recording, which has frames 0 to 9" in err
    assert "Traceback" not in err and not out.exists()


def test_marker_set_file_errors_name_the_file(tmp_path, capsys):
    path = tmp_path / "take.trc"
    labels, P, _ = _standing_markers(10)
    _write_trc(path, labels, P * 1000)
    for name, body, needle in (("role.toml", 'FOO = "LKNE"', "unknown marker role 'FOO'"),
                               ("label.toml", 'LKNE = "NOPE"', "marker 'NOPE' (for LKNE) is not in the recording")):
        ms = tmp_path / name
        ms.write_text(f"[markers]\n{body}\n")
        assert main(["solve", str(path), "--marker-set", str(ms), "-o", str(tmp_path / "a.bvh")]) == 2
        err = capsys.readouterr().err
        assert f"physmocap: error: {ms}: {needle}" in err and "Traceback" not in err
    assert not (tmp_path / "a.bvh").exists()


def test_markers_that_place_no_joint_are_one_error_and_no_file(tmp_path, capsys):
    labels, P, _ = _standing_markers(30)
    keep = [labels.index(k) for k in ("LFHD", "RFHD", "LKNE")]
    path = tmp_path / "head.trc"
    _write_trc(path, [labels[i] for i in keep], P[:, keep] * 1000)
    solve_fails_cleanly(capsys, path, tmp_path / "a.bvh", "the markers place none of the joints")


@pytest.mark.filterwarnings("ignore:.*joint centres from the anatomical regression")
def test_segments_without_markers_are_warned(tmp_path):
    labels, P, _ = _standing_markers(30)
    keep = [i for i, lab in enumerate(labels) if not lab.startswith(("LKNE", "LANK", "LHEE", "LTOE"))]
    path = tmp_path / "no_left_leg.trc"
    _write_trc(path, [labels[i] for i in keep], P[:, keep] * 1000)
    with pytest.warns(UserWarning, match=r"no_left_leg\.trc: no marker on 5 segment\(s\): left_thigh, left_shank, "
                      r"left_foot, left_hand, right_hand; they keep the actor.s rest pose"):
        assert main(["solve", str(path), "-o", str(tmp_path / "a.bvh"), "--quiet"]) == 0


def test_solve_refuses_bad_solve_options_before_reading(tmp_path, capsys):
    out = tmp_path / "a.bvh"
    assert main(["solve", str(tmp_path / "absent.c3d"), "-o", str(out), "--max-iterations", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "marker solve option max_iterations must be > 0, got 0" in err[0] and not out.exists()
