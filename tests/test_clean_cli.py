"""``physmocap clean``'s threshold flags: generated from :class:`CleanOptions`, validated
before any file is read, errors naming the flag (issue 12)."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from physmocap.cli import build_parser, main
from physmocap.clean import CleanOptions
from physmocap.clean.options import UNITS, option_docs, option_unit


def _clean_parser():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices["clean"]


def test_every_option_is_a_flag_with_its_unit_default_and_documentation():
    docs = option_docs()
    flags = {a.dest: a for a in _clean_parser()._actions}
    for f in dataclasses.fields(CleanOptions):
        assert f.name in docs and len(docs[f.name]) > 20, f.name  # documented in the class
        unit = option_unit(f.name)
        assert unit in UNITS
        action = flags[f.name]
        assert action.option_strings == ["--" + f.name.replace("_", "-")]
        assert action.default is None  # unset: the class's default, not a copy of it
        assert f"(default {f.default:g}" in action.help
        if unit not in ("ratio", "count"):
            assert f"{f.default:g} {unit})" in action.help and action.metavar == unit.upper()


def test_flags_build_the_options_and_unset_ones_keep_the_defaults():
    from physmocap.cli.clean import options_from_args

    args = _clean_parser().parse_args(["x.bvh", "--jump-deg", "12", "--match-windows", "2", "--still-speed", "3"])
    assert options_from_args(args) == CleanOptions(jump_deg=12.0, match_windows=2, still_speed=3.0)
    assert options_from_args(_clean_parser().parse_args(["x.bvh"])) == CleanOptions()


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--still-speed", "-1"], "--still-speed must be > 0, got -1.0"),
        (["--jump-deg", "nan"], "--jump-deg must be a finite number, got nan"),
        (["--match-windows", "0"], "--match-windows must be > 0, got 0"),
        (["--rom-soft-margin", "-5"], "--rom-soft-margin must be >= 0, got -5.0"),
        (["--match-windows", "1.5"], "--match-windows: invalid int value"),
        (["--plane-min-deg", "200"], "--plane-min-deg must be in (0, 90) degrees"),  # sin() folds back past 90
        (["--blend-ratio", "0.5"], "--blend-ratio must be at least 1"),
    ],
)
def test_a_bad_value_is_refused_naming_its_flag_before_the_file_is_read(tmp_path, capsys, argv, message):
    missing = tmp_path / "nope.bvh"  # never read: the options are checked first
    try:
        code = main(["clean", str(missing), *argv])
    except SystemExit as exc:  # argparse's own type check
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "not found" not in err


def test_a_flag_changes_what_is_found(tmp_path, capsys):
    """A joint held for 0.25 s is frozen by default (``frozen_time`` 0.1 s), not with
    ``--frozen-time 0.5``."""
    from physmocap.export.bvh import write_bvh
    from physmocap.sources import load_motion

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        walk = load_motion("example").slice_frames(0, 400)
    j = walk.skeleton.names.index("RightUpLeg")
    R = np.array(walk.rotations, copy=True)
    R[200:230, j] = R[199, j]
    src = write_bvh(dataclasses.replace(walk, rotations=R), tmp_path / "held.bvh", precision=9)

    def frozen(*flags: str) -> list:
        rep = tmp_path / "g.json"
        assert main(["clean", str(src), "--report", str(rep), *flags]) == 0
        return [(g["joint"], g["start"], g["end"]) for g in json.loads(rep.read_text())["glitches"] if g["kind"] == "frozen"]

    assert frozen() == [("RightUpLeg", 200, 229)]
    assert frozen("--frozen-time", "0.5") == []
    capsys.readouterr()


@pytest.mark.parametrize("name", ["vicon_upperbody.trc", "vicon_upperbody_box.c3d"])
def test_an_upper_body_take_is_refused_without_talk_of_a_character(tmp_path, capsys, name):
    """``clean`` has no character: an upper-body marker take is refused because the skeleton
    cannot be built without leg markers, not because it "cannot drive a character's legs"."""
    from conftest import shared_file

    out = tmp_path / "x.bvh"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["clean", str(shared_file(name)), "-o", str(out)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("physmocap: error:")]
    assert len(err) == 1 and "character" not in err[0], err
    assert (f"{shared_file(name)}: no marker on left_thigh, left_shank, left_foot, right_thigh, right_shank, "
            "right_foot: the legs were not captured (an upper-body take?), so a full-body skeleton cannot be "
            "built without leg markers; `physmocap solve FILE -o actor.bvh`") in err[0]
    assert not out.exists()
