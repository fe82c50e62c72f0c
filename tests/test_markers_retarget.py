"""Markers to a character through the solved actor (issue 11, deliverable 4): ``physmocap
retarget take.c3d`` and ``load_motion(take.c3d)`` solve the actor first; ``--joint-centres``
keeps the older joint-centre route; takes without legs are one clear error."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from conftest import shared_file
from physmocap.cli import build_parser, main
from test_markers import _c3d_copy, _standing_markers, _write_trc

pytestmark = pytest.mark.filterwarnings("ignore::physmocap.errors.PhysmocapWarning")


def _retarget_source(argv: list[str]):
    """The source motion ``physmocap retarget`` hands the retargeter for ``argv``."""
    from physmocap.cli.retarget import retarget_from_args

    return retarget_from_args(build_parser().parse_args(["retarget"] + argv)).source_motion


def test_retarget_takes_markers_through_the_solved_actor(tmp_path):
    c3d = tmp_path / "take.c3d"
    _c3d_copy(c3d, frames=240)
    out = str(tmp_path / "o.npz")
    solved = _retarget_source([str(c3d), "-o", out, "--character", "robot", "--quiet"])
    assert solved.is_rotational and "left_knee" in solved.skeleton.names
    assert solved.meta["character"] == "actor (physmocap solve)" and solved.meta["marker_residual_rms_mm"] < 15.0
    centres = _retarget_source([str(c3d), "-o", out, "--character", "robot", "--quiet", "--joint-centres"])
    assert not centres.is_rotational and "joint_centre_methods" in centres.meta


def test_retargeting_markers_is_deterministic(tmp_path):
    c3d = tmp_path / "take.c3d"
    _c3d_copy(c3d, frames=120)
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    for out in (a, b):
        assert main(["retarget", str(c3d), "-o", str(out), "--character", "robot", "--quiet"]) == 0
    assert a.read_bytes() == b.read_bytes()


def test_load_motion_solves_markers_by_default(tmp_path):
    from physmocap.sources import load_motion

    labels, P, _ = _standing_markers(40)
    path = tmp_path / "take.trc"
    _write_trc(path, labels, P * 1000)
    solved, centres = load_motion(path), load_motion(path, solve=False)
    assert solved.is_rotational and not centres.is_rotational
    with pytest.raises(Exception, match="do not apply to a solved marker recording"):
        load_motion(path, max_gap=3)


@pytest.mark.parametrize("name", ["vicon_upperbody.trc", "vicon_upperbody_box.c3d"])
def test_an_upper_body_take_cannot_drive_a_character_and_says_why(tmp_path, capsys, name):
    out = tmp_path / "o.bvh"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["retarget", str(shared_file(name)), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert (f"physmocap: error: {shared_file(name)}: no marker on left_thigh, left_shank, left_foot, right_thigh, "
            "right_shank, right_foot: the legs were not captured (an upper-body take?), so they cannot drive a "
            "character's legs") in err
    assert "Traceback" not in err and not out.exists()


def test_joint_centres_flag_is_for_marker_files(tmp_path, capsys):
    out = tmp_path / "o.bvh"
    assert main(["retarget", "example", "-o", str(out), "--joint-centres"]) == 2
    err = capsys.readouterr().err
    assert "--joint-centres: for marker files only" in err and "Traceback" not in err and not out.exists()


def test_retarget_passes_the_marker_solve_options_of_solve(tmp_path):
    """``--marker-max-iterations`` / ``--marker-no-floor`` reach the actor's solve as the
    MarkerSolveOptions that ``physmocap solve --max-iterations / --no-floor`` builds; the
    character's ``--max-iterations`` stays the character's."""
    from physmocap.markers.motion import solved_motion
    from physmocap.markers.solve import MarkerSolveOptions
    from physmocap.sources.markers import read_markers

    c3d = tmp_path / "take.c3d"
    _c3d_copy(c3d, frames=120)
    argv = [str(c3d), "-o", str(tmp_path / "o.npz"), "--character", "robot", "--quiet", "--max-iterations", "3"]
    solved = _retarget_source(argv + ["--marker-max-iterations", "5", "--marker-no-floor"])
    want = MarkerSolveOptions(max_iterations=5, floor=False)
    assert solved.meta["marker_solve_options"] == dataclasses.asdict(want)
    direct = solved_motion(read_markers(c3d), solve_options=want)
    assert np.array_equal(solved.rotations, direct.rotations)
    default = _retarget_source(argv)
    assert default.meta["marker_solve_options"] == dataclasses.asdict(MarkerSolveOptions())
    assert not np.array_equal(default.rotations, solved.rotations)


@pytest.mark.parametrize("argv,needle", [
    (["example", "--marker-no-floor"], "example: --marker-max-iterations / --marker-no-floor: for marker files only"),
    (["example", "--marker-set", "{SET}"], "example: --marker-set: for marker files only"),
    (["{C3D}", "--marker-max-iterations", "0"], "marker solve option max_iterations must be > 0, got 0"),
    (["{C3D}", "--joint-centres", "--marker-no-floor"], "shape the actor's solve, which --joint-centres skips"),
])
def test_bad_marker_solve_options_are_one_error(tmp_path, capsys, argv, needle):
    c3d = tmp_path / "take.c3d"
    _c3d_copy(c3d, frames=60)
    out = tmp_path / "o.bvh"
    (tmp_path / "set.toml").write_text('[markers]\nLKNE = "LKNE"\n')
    args = [a.replace("{C3D}", str(c3d)).replace("{SET}", str(tmp_path / "set.toml")) for a in argv]
    assert main(["retarget", *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and not out.exists()


def test_marker_solve_options_are_validated_when_made():
    from physmocap.errors import OptionError
    from physmocap.markers.solve import MarkerSolveOptions

    for bad in ({"max_iterations": 0}, {"max_iterations": 1.5}, {"floor": "no"}, {"rigidity": -0.01},
                {"calibration_frames": float("nan")}):
        with pytest.raises(OptionError, match="marker solve option"):
            MarkerSolveOptions(**bad)
    with pytest.raises(dataclasses.FrozenInstanceError):
        MarkerSolveOptions().floor = False


def test_batch_applies_its_marker_options_to_its_marker_files_only(tmp_path):
    """A folder mixing a skeleton file and a marker file: ``--marker-set`` and the marker solve's
    options reach the marker file and leave the BVH alone (a BVH used to fail with a TypeError
    on --marker-set)."""
    import json
    import shutil

    from physmocap.resources import resolve_input

    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(resolve_input("example"), folder / "walk.bvh")
    _c3d_copy(folder / "take.c3d", frames=120)
    (tmp_path / "set.toml").write_text('[markers]\nLKNE = "LKNE"\n')
    argv = ["batch", str(folder), "-o", str(tmp_path / "out"), "--end", "30", "--quiet", "--jobs", "1",
            "--marker-set", str(tmp_path / "set.toml"), "--marker-max-iterations", "3", "--marker-no-floor"]
    assert main(argv) == 0
    rows = json.loads((tmp_path / "out" / "summary.json").read_text())["files"]
    assert sorted(r["status"] for r in rows) == ["done", "done"]
