"""Bad characters and mapping files: one clear error naming the file and the entry."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from physmocap.errors import InputError, MappingError
from physmocap.models import load_character

FIXTURES = Path(__file__).parent / "fixtures"


@pytest.fixture
def biped(tmp_path):
    """A writable copy of the fixture biped and its mapping file."""
    xml = tmp_path / "biped.xml"
    shutil.copy(FIXTURES / "biped.xml", xml)
    mp = tmp_path / "biped.map.toml"
    shutil.copy(FIXTURES / "biped.map.toml", mp)
    return xml, mp


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_mjcf_that_does_not_load(tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<mujoco><worldbody><body name='a'><geom size='0.1'/></body></worldbod></mujoco>")
    with pytest.raises(InputError) as e:
        load_character(bad)
    assert str(bad) in str(e.value) and "MuJoCo cannot load" in str(e.value)
    assert "\n" not in str(e.value)


def test_missing_mjcf_and_unknown_name(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_character(tmp_path / "nope.xml")
    with pytest.raises(InputError, match="bundled characters are"):
        load_character("no_such_character")


def test_site_that_does_not_exist(biped):
    xml, mp = biped
    _edit(mp, 'left_knee = "body:shinL"', 'left_knee = "site:knee_l"')
    with pytest.raises(MappingError) as e:
        load_character(xml)
    msg = str(e.value)
    assert msg.startswith(f"{mp}:")
    assert "[joints] left_knee" in msg and "no site 'knee_l'" in msg
    line = int(msg[len(str(mp)) + 1 :].split(":")[0])
    assert 'left_knee = "site:knee_l"' in mp.read_text().splitlines()[line - 1]


def test_body_that_does_not_exist(biped):
    xml, mp = biped
    _edit(mp, 'chest = "torso"', 'chest = "ribcage"')
    with pytest.raises(MappingError, match=r"\[joints\] chest: the model has no site or body 'ribcage'"):
        load_character(xml)


def test_required_joint_unmapped(biped):
    xml, mp = biped
    _edit(mp, 'right_elbow = "body:forearmR"\n', "")
    with pytest.raises(MappingError) as e:
        load_character(xml)
    assert str(mp) in str(e.value) and "right_elbow" in str(e.value)


def test_joint_without_limits_where_required(biped):
    xml, mp = biped
    _edit(mp, "kneeR = [-2, 150]\n", "")
    with pytest.raises(MappingError) as e:
        load_character(xml)
    assert str(xml) in str(e.value) and "'kneeR' has no range" in str(e.value)
    # the same file is fine when the mapping does not ask for limits
    _edit(mp, "require_limits = true", "require_limits = false")
    ch = load_character(xml)
    assert ch.joint_limits["kneeR"] == (float("-inf"), float("inf"))
    # or asks only for some joints
    _edit(mp, "require_limits = false", 'require_limits = ["kneeL", "kneeR"]')
    with pytest.raises(MappingError, match="'kneeR' has no range"):
        load_character(xml)


def test_unknown_canonical_name(biped):
    xml, mp = biped
    _edit(mp, "[joints]\n", '[joints]\nleft_pinky = "body:handL"\n')
    with pytest.raises(MappingError, match=r"\[joints\] left_pinky: not a canonical joint"):
        load_character(xml)


def test_bad_toml_names_the_line(biped):
    xml, mp = biped
    _edit(mp, 'neck = "body:skull"', "neck = body:skull")
    with pytest.raises(InputError) as e:
        load_character(xml)
    assert str(e.value).startswith(f"{mp}:") and "not valid TOML" in str(e.value)


def test_bad_values(biped):
    xml, mp = biped
    _edit(mp, 'up = "Y"', 'up = "W"')
    with pytest.raises(MappingError, match=r"\[character\] up: expected one of"):
        load_character(xml)
    _edit(mp, 'up = "W"', 'up = "Z"')
    _edit(mp, 'forward = "Z"', 'forward = "-Z"')
    with pytest.raises(MappingError, match="parallel"):
        load_character(xml)


def test_contact_site_missing(biped):
    xml, mp = biped
    _edit(mp, '"footL_toe"]', '"footL_tip"]')
    with pytest.raises(MappingError, match=r"\[contacts\] left: the model has no site 'footL_tip'"):
        load_character(xml)


def test_limit_override_for_missing_joint(biped):
    xml, mp = biped
    _edit(mp, "kneeL = [-2, 150]", "knee_left = [-2, 150]")
    with pytest.raises(MappingError, match=r"\[joint_limits\] knee_left: the model has no joint"):
        load_character(xml)


def test_explicit_map_not_found(biped, tmp_path):
    xml, _ = biped
    with pytest.raises(InputError, match="mapping file not found"):
        load_character(xml, tmp_path / "missing.map.toml")


def test_no_mapping_file_at_all(biped):
    """Issue 13: with no mapping file the proposed mapping is used, and said so."""
    xml, mp = biped
    mp.unlink()
    with pytest.warns(Warning, match="no mapping file found: using the mapping"):
        ch = load_character(xml)
    assert ch.mapping_proposed and ch.map_path is None


def test_no_mapping_file_and_nothing_to_propose(tmp_path):
    """A model the proposer cannot read as a humanoid still gets the missing-mapping error."""
    xml = tmp_path / "blob.xml"
    xml.write_text(
        '<mujoco><worldbody><body name="blob"><freejoint/><geom type="sphere" size="0.1"/>'
        '<body name="arm" pos="0 0 0.2"><joint type="hinge"/><geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.03"/>'
        "</body></body></worldbody></mujoco>"
    )
    with pytest.raises(MappingError) as e:
        load_character(xml)
    assert str(xml) in str(e.value) and "no mapping file" in str(e.value)


def test_rest_pose_outside_limits(biped):
    xml, mp = biped
    mp.write_text(mp.read_text() + "\n[rest.joints]\nelbowL = 30\n")
    with pytest.raises(MappingError, match="rest pose puts joint 'elbowL'"):
        load_character(xml)


@pytest.mark.parametrize("command", [["character", "info"], ["character", "init"], ["retarget", "example", "--character"]])
def test_mujocos_own_warnings_leave_no_log_file(tmp_path, monkeypatch, capsys, command):
    """MuJoCo's default handler wrote MUJOCO_LOG.TXT into the working folder and printed its
    warning on stdout ('XML contains a NaN'): they are physmocap's to report, on stderr."""
    from physmocap.cli import main

    text = (FIXTURES / "biped.xml").read_text()
    at = text.index('pos="') + len('pos="')
    bad = tmp_path / "nan.xml"
    bad.write_text(text[:at] + "nan " + text[at:])
    monkeypatch.chdir(tmp_path)
    assert main([*command, str(bad), *(["-o", str(tmp_path / "x.npz")] if command[0] == "retarget" else [])]) == 2
    out, err = capsys.readouterr()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "NaN" not in out and "MuJoCo cannot load this MJCF" in err and "Traceback" not in err


def test_a_model_that_loads_passes_mujocos_warning_on(tmp_path, monkeypatch, capfd):
    """A model MuJoCo loads with a warning (a NaN colour) loads, and the warning is a
    physmocap warning naming the file, not MuJoCo's print on stdout and its log file."""
    from physmocap.errors import PhysmocapWarning
    from physmocap.models.character import read_mjcf

    bad = tmp_path / "nan_rgba.xml"
    bad.write_text('<mujoco><worldbody><body name="b"><freejoint/>'
                   '<geom type="sphere" size="0.1" rgba="nan 0 0 1"/></body></worldbody></mujoco>')
    monkeypatch.chdir(tmp_path)
    with pytest.warns(PhysmocapWarning, match=r"nan_rgba\.xml: MuJoCo: XML contains a 'NaN'"):
        model = read_mjcf(bad)
    assert model.ngeom == 1
    assert "NaN" not in capfd.readouterr().out
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
