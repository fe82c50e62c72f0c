"""``physmocap character info`` and ``physmocap character scale``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from physmocap.cli import main

FIXTURES = Path(__file__).parent / "fixtures"


def test_info_default(capsys):
    assert main(["character", "info"]) == 0
    out = capsys.readouterr().out
    assert "character  humanoid" in out
    assert "total mass 70.00 kg" in out
    assert "left_knee_flexion" in out and "[   -10.0,   165.0]" in out
    assert "left_heel" in out and "left_hip -> left_knee" in out


def test_info_robot_and_fixture(capsys):
    assert main(["character", "info", "robot"]) == 0
    out = capsys.readouterr().out
    assert "character  robot" in out and "l_hip_yaw" in out and "height     1.300 m" in out
    assert main(["character", "info", str(FIXTURES / "biped.xml"), "--map", str(FIXTURES / "biped.map.toml")]) == 0
    assert "stilt_biped" in capsys.readouterr().out


def test_info_json(capsys):
    assert main(["character", "info", "--json", "--range-policy", "strict"]) == 0
    desc = json.loads(capsys.readouterr().out)
    knee = next(j for j in desc["joints"] if j["name"] == "left_knee_flexion")
    assert knee["range"] == pytest.approx([0.0, 135.0])
    assert knee["units"] == "deg, deg/s"
    assert desc["contacts"]["left"] == ["left_heel", "left_ball", "left_toe_tip"]
    assert desc["total_mass"] == pytest.approx(70.0)
    assert ["right_shoulder_flexion", "right_shoulder_abduction", "right_shoulder_rotation"] in desc["velocity_groups"]


def test_info_names_the_hinge_groups_on_the_humanoid_only(capsys):
    assert main(["character", "info"]) == 0
    out = capsys.readouterr().out
    assert "the body's angular speed along each axis" in out and "left_hip_flexion, left_hip_adduction, left_hip_rotation" in out
    assert main(["character", "info", "robot"]) == 0
    assert "angular speed" not in capsys.readouterr().out  # motors: each hinge's own rate


def test_info_bad_mapping_is_one_line(tmp_path, capsys):
    mp = tmp_path / "bad.map.toml"
    mp.write_text((FIXTURES / "biped.map.toml").read_text().replace("body:shinL", "site:nope"))
    assert main(["character", "info", str(FIXTURES / "biped.xml"), "--map", str(mp)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(mp) in err and "left_knee" in err and "nope" in err


def test_scale(tmp_path, capsys):
    out = tmp_path / "actor.xml"
    assert main(["character", "scale", "-o", str(out), "--height", "1.6",
                 "--segment", "left_hip:left_knee=0.41", "--mass", "55"]) == 0
    assert out.exists() and (tmp_path / "actor.map.toml").exists()
    capsys.readouterr()
    assert main(["character", "info", str(out), "--json"]) == 0
    desc = json.loads(capsys.readouterr().out)
    seg = {(s["parent"], s["child"]): s["length"] for s in desc["segment_lengths"]}
    assert seg[("right_hip", "right_knee")] == pytest.approx(0.41)
    assert desc["total_mass"] == pytest.approx(55.0, rel=1e-4)
    assert main(["character", "scale", "-o", str(out), "--segment", "hip=0.4"]) == 2
