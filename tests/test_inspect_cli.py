"""``physmocap inspect``: text and JSON reports, forced profiles, mapping files, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_BVH, shared_file
from physmocap.canonical import CANONICAL_NAMES
from physmocap.cli import main
from physmocap.errors import PhysmocapWarning
from physmocap.motion import Skeleton
from physmocap.sources import load_motion

FIXTURES = Path(__file__).parent / "fixtures" / "profiles"


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_example_text_report(capsys):
    status, out, err = run(capsys, "inspect", "example")
    assert status == 0
    assert "file:      example (BVH, rotational)" in out  # the bundled clip by the name given, not its installed path
    assert "frames:    524 at 120 fps, 4.367 s" in out
    assert "units:     cmu (0.0564444 m per file unit, detected); file up axis Y" in out
    assert "height:    1.365 m (rest pose)" in out
    assert "floor:     " in out
    # the tree, with channels and canonical joints
    assert "  Hips  [Xposition Yposition Zposition Zrotation Yrotation Xrotation]  -> pelvis" in out
    assert "\n    LHipJoint  [Zrotation Yrotation Xrotation]\n" in out
    assert "      LeftUpLeg  [Zrotation Yrotation Xrotation]  -> left_hip" in out
    assert "LeftToeBase_End (end site)  -> left_toe_end" in out
    assert "profile:   cmu: CMU Graphics Lab" in out
    assert "  neck            Neck1\n" in out
    assert "unmapped:  none" in out
    assert err == ""


@pytest.mark.parametrize("name", SHARED_BVH)
def test_json_report_of_each_recording(capsys, name):
    path = shared_file(name)
    status, out, err = run(capsys, "inspect", str(path), "--json")
    assert status == 0
    rep = json.loads(out)
    motion = load_motion(path)
    assert rep["frames"] == motion.num_frames
    assert rep["fps"] == pytest.approx(motion.fps, rel=1e-6)
    assert rep["duration_s"] == pytest.approx(motion.duration, rel=1e-6)
    assert rep["units"] == motion.units and rep["file_up"] == "Y"
    assert rep["kind"] == "rotational" and rep["format"] == "bvh"
    assert rep["floor_m"] == pytest.approx(motion.floor_height(), abs=1e-6)
    assert 1.2 < rep["height_m"] < 2.0
    assert rep["missing_required"] == []
    assert list(rep["mapping"]) == list(CANONICAL_NAMES)
    assert rep["mapping"]["left_knee"] == {"source": "LeftLeg", "index": motion.skeleton.index("LeftLeg")}
    assert len(rep["joints"]) == motion.skeleton.num_joints
    hips = rep["joints"][0]
    assert hips["name"] == "Hips" and hips["parent"] is None and hips["canonical"] == "pelvis"
    assert hips["channels"][:3] == ["Xposition", "Yposition", "Zposition"]
    assert all(j["channels"] is None for j in rep["joints"] if j["end_site"])
    # same input, same bytes
    again = run(capsys, "inspect", str(path), "--json")[1]
    assert again == out


def test_forced_profile_and_units(capsys):
    path = shared_file("optitrack_hops_crouch.bvh")
    status, out, _ = run(capsys, "inspect", str(path), "--profile", "cmu", "--units", "cm", "--json")
    assert status == 0
    rep = json.loads(out)
    assert rep["profile"] == "cmu" and rep["units"] == "cm" and rep["units_detected"] is False
    assert rep["height_m"] == pytest.approx(0.01 * 1.744529, rel=1e-4)


def test_mapping_file_and_emit_map_round_trip(capsys, tmp_path):
    path = shared_file("pymo_walk.bvh")
    status, toml, _ = run(capsys, "inspect", str(path), "--emit-map")
    assert status == 0
    assert 'profile = "pymo"' in toml and 'neck = "Head"' in toml and "# chest = ..." in toml
    mp = tmp_path / "pymo.toml"
    mp.write_text(toml.replace('left_hand_end = "LeftHand_End"', 'left_hand_end = false'))
    status, out, _ = run(capsys, "inspect", str(path), "--map", str(mp), "--json")
    rep = json.loads(out)
    assert status == 0 and rep["profile"] == "custom" and rep["based_on"] == "pymo"
    assert rep["mapping"]["left_hand_end"] is None
    assert rep["mapping"]["right_hand_end"]["source"] == "RightHand_End"


def test_bad_inputs_fail_with_one_line(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[joints]\nneck = = 3\n")
    status, out, err = run(capsys, "inspect", "example", "--map", str(bad))
    assert status == 2 and out == ""
    assert err.startswith(f"physmocap: error: {bad}:2: not valid TOML") and err.count("\n") == 1
    status, _, err = run(capsys, "inspect", "example", "--profile", "nosuch")
    assert status == 2 and "unknown skeleton profile 'nosuch'" in err
    status, _, err = run(capsys, "inspect", str(tmp_path / "missing.bvh"))
    assert status == 2 and "file not found" in err


def test_unmappable_skeleton_is_described_then_fails(capsys, tmp_path):
    """An armless skeleton: the report is printed, then the missing joints are named."""
    skel = load_motion(FIXTURES / "xsens_mvn.bvh").skeleton
    keep = [j for j, n in enumerate(skel.names) if not any(s in n for s in ("Collar", "Shoulder",
                                                                            "Elbow", "Wrist"))]
    sub = skel.subset(keep)
    path = tmp_path / "armless.bvh"
    _write_bvh(sub, path)
    status, out, err = run(capsys, "inspect", str(path))
    assert status == 2
    assert "profile:   xsens" in out
    assert "unmapped:  left_clavicle, right_clavicle, left_shoulder (required)" in out
    assert err.startswith(f"physmocap: error: {path}: cannot map the required canonical joint(s) "
                          "left_shoulder, right_shoulder, left_elbow, right_elbow, left_wrist, right_wrist")
    assert "Hips, Chest, Chest2" in err
    # --emit-map still writes the partial map to fill in, with a warning
    with pytest.warns(PhysmocapWarning, match="still unmapped: left_shoulder"):
        status, toml, err = run(capsys, "inspect", str(path), "--emit-map")
    assert status == 0 and "# left_shoulder = ..." in toml


def test_scrambled_names_inspect_by_topology(capsys, tmp_path):
    skel = load_motion(shared_file("cmu_12_01_walk.bvh")).skeleton
    rng = np.random.default_rng(3)
    names = tuple(f"bone{k:02d}" for k in rng.permutation(skel.num_joints))
    anon = Skeleton(names, skel.parents, skel.offsets, skel.end_site)
    path = tmp_path / "anon.bvh"
    _write_bvh(anon, path)
    status, out, _ = run(capsys, "inspect", str(path), "--units", "m", "--json")
    rep = json.loads(out)
    assert status == 0 and rep["profile"] == "topology"
    hip = rep["mapping"]["left_hip"]["source"]
    assert hip == names[skel.index("LeftUpLeg")]


def _write_bvh(skel: Skeleton, path: Path) -> None:
    """A minimal BVH (metres, Y up) of ``skel``'s rest pose, two frames."""
    from physmocap.rotations import up_axis_matrix

    R = up_axis_matrix("Z", "Y")
    lines = ["HIERARCHY"]
    kids = [[c for c in range(skel.num_joints) if skel.parents[c] == j] for j in range(skel.num_joints)]
    nchan = 0

    def emit(j, depth):
        nonlocal nchan
        ind = "  " * depth
        off = R @ skel.offsets[j]
        if skel.end_site[j]:
            lines.extend([f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}",
                          f"{ind}}}"])
            return
        lines.append(f"{ind}{'ROOT' if skel.parents[j] < 0 else 'JOINT'} {skel.names[j]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if skel.parents[j] < 0:
            lines.append(f"{ind}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
            nchan += 6
        else:
            lines.append(f"{ind}  CHANNELS 3 Zrotation Xrotation Yrotation")
            nchan += 3
        for c in kids[j]:
            emit(c, depth + 1)
        lines.append(f"{ind}}}")

    emit(0, 0)
    row = " ".join(["0"] * nchan)
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0333333", row, row]
    path.write_text("\n".join(lines) + "\n")
