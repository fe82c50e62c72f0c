"""BVH reader: real recordings, vendor-style fixtures, grammar corners, options."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import bvh_reference
from conftest import SHARED_BVH, shared_file
from physmocap.errors import OptionError, PhysmocapWarning
from physmocap.resources import example_clip
from physmocap.rotations import euler_to_quat
from physmocap.sources import bvh as bvh_mod
from physmocap.sources import load_motion
from physmocap.sources.bvh import CMU_UNIT, detect_units, read_bvh, resolve_units

FIXTURES = Path(__file__).parent / "fixtures" / "bvh"

#: file -> (frames, joints incl. end sites, channels per frame, units, fps)
SHARED_EXPECT = {
    "cmu_01_01_jumps.bvh": (2752, 31 + 7, 96, "cmu", 1 / 0.0083333),
    "cmu_12_01_walk.bvh": (524, 31 + 7, 96, "cmu", 1 / 0.0083333),
    "optitrack_hops_crouch.bvh": (3146, 21 + 5, 66, "m", 1 / 0.008333),
    "pymo_walk.bvh": (1064, 23 + 7, 72, "inch", 1 / 0.008333),
}


def _num_channels(m) -> int:
    return sum(len(c) for c in m.meta["bvh_channels"].values())


@pytest.mark.parametrize("name", SHARED_BVH)
def test_shared_files_read(name):
    path = shared_file(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)  # clean files: no warnings
        m = read_bvh(path)
    frames, joints, channels, units, fps = SHARED_EXPECT[name]
    assert m.num_frames == frames
    assert m.skeleton.num_joints == joints
    assert _num_channels(m) == channels
    assert m.units == units
    assert m.fps == pytest.approx(fps)
    assert m.file_up == "Y" and m.source == str(path)
    assert m.meta["frames_declared"] == frames
    assert m.rotations.shape == (frames, joints, 4)
    np.testing.assert_allclose(np.linalg.norm(m.rotations, axis=-1), 1.0, atol=1e-12)
    # Every end site is a leaf named after its parent.
    sk = m.skeleton
    for j in np.flatnonzero(sk.end_site):
        assert not sk.children(int(j))
        assert sk.names[j].startswith(sk.names[sk.parents[j]] + "_End")
    # Human-sized, Z-up, standing on a floor near z = 0.
    pos = m.world_positions()
    assert np.isfinite(pos).all()
    assert 1.2 < sk.height() < 2.1
    head = sk.index("Head")
    hips = sk.index("Hips")
    assert np.all(pos[:, head, 2] > pos[:, hips, 2])
    assert abs(m.floor_height()) < 0.1
    assert 1.3 < pos[..., 2].max() < 2.3


def test_shared_quirks():
    walk = read_bvh(shared_file("cmu_12_01_walk.bvh"))  # CRLF (mixed) line endings
    assert walk.skeleton.names[:3] == ("Hips", "LHipJoint", "LeftUpLeg")
    assert walk.meta["frame_time"] == pytest.approx(0.0083333)  # ".0083333"
    assert walk.meta["bvh_rotation_orders"]["Hips"] == "ZYX"
    assert walk.unit_scale == pytest.approx(0.056444, rel=1e-5)
    opti = read_bvh(shared_file("optitrack_hops_crouch.bvh"))  # "Frames:    3146"
    assert opti.meta["bvh_rotation_orders"]["Spine"] == "ZXY"
    assert opti.meta["bvh_channels"]["Hips"] == [
        "Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"
    ]
    pymo = read_bvh(shared_file("pymo_walk.bvh"))
    # A joint named LeftHand_End exists: end-site naming must not collide with it.
    names = pymo.skeleton.names
    assert "LeftHand_End" in names and "LeftHand_End_End" in names
    assert not pymo.skeleton.end_site[names.index("LeftHand_End")]
    # Zero-length thumb bones are fine.
    assert np.allclose(pymo.skeleton.offsets[names.index("LeftHandThumb1")], 0.0)


def _reference_fk(path: Path, frames: list[int]) -> np.ndarray:
    """World positions (file units and axes) by a deliberately simple, independent FK
    (:mod:`bvh_reference`)."""
    return bvh_reference.world(bvh_reference.parse(path), frames)[1]


@pytest.mark.parametrize("name", SHARED_BVH)
def test_world_positions_match_independent_fk(name):
    path = shared_file(name)
    m = read_bvh(path)
    frames = [0, m.num_frames // 2, m.num_frames - 1]
    ref = _reference_fk(path, frames)  # file units, Y-up
    M = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    expect = ref @ M.T * m.unit_scale
    np.testing.assert_allclose(m.world_positions()[frames], expect, atol=1e-9 * m.skeleton.height())


def test_root_translation_and_axes_are_converted():
    """Frame values (file units, Y-up) map to metres, Z-up: (x, y, z) -> s (x, -z, y)."""
    path = shared_file("optitrack_hops_crouch.bvh")
    m = read_bvh(path)
    with open(path) as fh:
        lines = fh.read().split("\n")
    first = [float(v) for v in lines[lines.index("MOTION") + 3].split()]
    x, y, z = first[:3]
    np.testing.assert_allclose(m.translations[0, 0], [x, -z, y], atol=1e-12)
    # Rotation: R_world = M R_file M^T with ZXY channels.
    R_file = Rotation.from_euler("ZXY", first[3:6], degrees=True).as_matrix()
    M = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    np.testing.assert_allclose(Rotation.from_quat(m.rotations[0, 0]).as_matrix(), M @ R_file @ M.T, atol=1e-12)


def test_example_clip_loads():
    m = load_motion("example")
    assert m.source == str(example_clip())
    assert m.num_frames == 524 and m.units == "cmu"


# -- vendor-style fixtures ----------------------------------------------------------

VENDORS = {
    # file: (units, fps, a joint that must exist, joints with position channels)
    "cmu_cgspeed.bvh": ("cmu", 120.0, "LHipJoint", 1),
    "optitrack_motive.bvh": ("cm", 120.0, "LeftToeBase", 1),
    "vicon_blade.bvh": ("mm", 120.0, "Spine2", 22),
    "xsens_mvn.bvh": ("cm", 60.0, "Chest4", 1),
    "mocapbank.bvh": ("cm", 120.0, "RightToeBase", 1),
    "mixamo.bvh": ("cm", 30.0, "mixamorig:HeadTop_End", 1),
    "lafan1.bvh": ("cm", 30.0, "LeftToe", 22),
    "bandai_namco.bvh": ("cm", 30.0, "joint_Root", 22),
    "daz_poser.bvh": ("inch", 30.0, "rShldr", 1),
    "perception_neuron.bvh": ("cm", 60.0, "RightInHandIndex", 35),
}


@pytest.mark.parametrize("name", sorted(VENDORS))
def test_vendor_fixtures(name):
    units, fps, joint, n_translated = VENDORS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        m = read_bvh(FIXTURES / name)
    assert m.units == units
    assert m.fps == pytest.approx(fps, rel=1e-3)
    assert joint in m.skeleton.names
    assert len(m.translated) == n_translated
    assert m.num_frames == m.meta["frames_declared"] >= 4
    pos = m.world_positions()
    assert np.isfinite(pos).all()
    # A standing human, metres, Z-up: 1.4-2.1 m tall, feet near the floor.
    span = pos[..., 2].max(axis=1) - pos[..., 2].min(axis=1)
    assert np.all((span > 1.2) & (span < 2.2)), span
    assert abs(m.floor_height(0)) < 0.15
    # Same world positions as the independent reference FK.
    up = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    ref = _reference_fk(FIXTURES / name, list(range(m.num_frames))) @ up.T * m.unit_scale
    np.testing.assert_allclose(pos, ref, atol=1e-9)


def test_vendor_specifics():
    mix = read_bvh(FIXTURES / "mixamo.bvh")
    assert mix.skeleton.names[0] == "mixamorig:Hips"
    assert "mixamorig:HeadTop_End_End" in mix.skeleton.names  # end site of a joint named *_End
    daz = read_bvh(FIXTURES / "daz_poser.bvh")
    orders = daz.meta["bvh_rotation_orders"]
    assert orders["hip"] == "ZYX" and orders["abdomen"] == "XYZ" and orders["rCollar"] == "YZX"
    bn = read_bvh(FIXTURES / "bandai_namco.bvh")
    assert bn.skeleton.names[:2] == ("joint_Root", "Hips")
    np.testing.assert_allclose(bn.world_positions()[:, 0, 2], 0.0, atol=1e-12)  # wrapper on the floor
    pn = read_bvh(FIXTURES / "perception_neuron.bvh")
    assert pn.meta["bvh_rotation_orders"]["Hips"] == "YXZ"
    assert pn.meta["frame_time"] == pytest.approx(0.016667)
    xs = read_bvh(FIXTURES / "xsens_mvn.bvh")  # CRLF throughout
    assert [n for n in xs.skeleton.names if n.startswith("Chest")] == ["Chest", "Chest2", "Chest3", "Chest4"]
    mb = read_bvh(FIXTURES / "mocapbank.bvh")  # exponent notation everywhere
    assert mb.meta["frame_time"] == pytest.approx(8.333333e-3)
    blade = read_bvh(FIXTURES / "vicon_blade.bvh")  # position channels on every joint
    assert all(ch[:3] == ["Xposition", "Yposition", "Zposition"] for ch in blade.meta["bvh_channels"].values())


# -- grammar corners (hand-written edge_cases.bvh) ----------------------------------


def test_edge_cases_structure():
    m = read_bvh(FIXTURES / "edge_cases.bvh")
    assert m.skeleton.names == (
        "Reference", "Hips", "Spine", "Head", "Head_End", "Hand", "Hand_End2", "Hand_End3",
        "Hand_End", "Hand_End_End", "LeftLeg", "LeftLeg_End", "RightLeg", "RightLeg_End",
        "Prop", "Prop_End",
    )
    assert m.skeleton.roots() == [0, 14]  # two ROOTs
    assert list(m.translated) == [1, 5, 14]
    assert m.num_frames == 3  # blank lines between rows are skipped
    assert m.fps == pytest.approx(1 / 3.3333e-2)
    assert m.units == "cm"
    ch = m.meta["bvh_channels"]
    assert ch["Reference"] == ["Yrotation"]  # a root with rotation channels only
    assert ch["Hips"][0] == "Zrotation" and ch["Hips"][1:4] == ["Xposition", "Yposition", "Zposition"]
    assert ch["Hand_End"] == ["Zrotation"]  # lower-case "zrotation" accepted
    assert ch["RightLeg"] == []
    assert m.meta["bvh_rotation_orders"]["Spine"] == "XZ"


def test_edge_cases_values():
    m = read_bvh(FIXTURES / "edge_cases.bvh")
    pos = m.world_positions()
    names = m.skeleton.names
    at = {n: pos[:, i] for i, n in enumerate(names)}
    # Frame 0: every rotation zero, so the rest pose (cm, Y-up -> m, Z-up).
    np.testing.assert_allclose(at["Head_End"][0], [0, 0.005, 1.70], atol=1e-12)
    np.testing.assert_allclose(at["Hand_End3"][0], [0.40, -0.075, 1.40], atol=1e-12)
    np.testing.assert_allclose(at["Prop_End"][0], [0.5, 0.0, 1.10], atol=1e-12)
    # Frame 1: the wrapper root turns 90 degrees about the vertical; Hips moved
    # to x = 10 cm, and Hand's Yposition channel (25) replaces its offset's 20
    # while its X and Z keep the offset's 40 and 0.
    np.testing.assert_allclose(at["Hips"][1], [0, 0.10, 0.95], atol=1e-12)
    np.testing.assert_allclose(at["Hand"][1], [-0.005, 0.50, 1.45], atol=1e-12)
    np.testing.assert_allclose(m.translations[1, 1], [0.40, 0.0, 0.25], atol=1e-12)  # Hand, Z-up


def test_edge_cases_rotation_subsets():
    """One- and two-axis channel lists are the product of those axes in order."""
    m = read_bvh(FIXTURES / "edge_cases.bvh")
    names = m.skeleton.names
    M = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    spine = Rotation.from_quat(m.rotations[2, names.index("Spine")]).as_matrix()
    expect = Rotation.from_euler("XZ", [4, 2.5], degrees=True).as_matrix()
    np.testing.assert_allclose(spine, M @ expect @ M.T, atol=1e-12)
    ref = Rotation.from_quat(m.rotations[2, 0]).as_matrix()
    np.testing.assert_allclose(ref, M @ Rotation.from_euler("Y", 12.5, degrees=True).as_matrix() @ M.T, atol=1e-12)


# -- line endings, encodings, chunking --------------------------------------------


def _variant(tmp_path: Path, data: bytes, name: str = "v.bvh") -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    return p


@pytest.mark.parametrize("kind", ["crlf", "cr", "bom", "tabs", "frames_after_time"])
def test_text_variants_read_the_same(tmp_path, kind):
    src = (FIXTURES / "optitrack_motive.bvh").read_bytes()
    ref = read_bvh(FIXTURES / "optitrack_motive.bvh")
    if kind == "crlf":
        data = src.replace(b"\n", b"\r\n")
    elif kind == "cr":
        data = src.replace(b"\n", b"\r")
    elif kind == "bom":
        data = b"\xef\xbb\xbf" + src
    elif kind == "tabs":
        data = src.replace(b"  ", b"\t \t")
    else:
        data = src.replace(b"Frames:    5\nFrame Time:    0.008333", b"Frame Time: 0.008333\n\nFrames: 5")
    m = read_bvh(_variant(tmp_path, data))
    np.testing.assert_array_equal(m.rotations, ref.rotations)
    np.testing.assert_array_equal(m.translations, ref.translations)
    assert m.skeleton.names == ref.skeleton.names


def test_chunked_reading_matches(tmp_path, monkeypatch):
    """Tiny chunks (many chunk boundaries, rows split across reads) give the same motion."""
    path = shared_file("cmu_12_01_walk.bvh")
    ref = read_bvh(path)
    monkeypatch.setattr(bvh_mod, "CHUNK_BYTES", 997)
    m = read_bvh(path)
    np.testing.assert_array_equal(m.rotations, ref.rotations)
    np.testing.assert_array_equal(m.translations, ref.translations)


def test_slow_path_matches_fast_path(tmp_path):
    """A chunk the fast parser refuses (a form feed) is read exactly by the slow pass."""
    src = (FIXTURES / "cmu_cgspeed.bvh").read_bytes()
    ref = read_bvh(FIXTURES / "cmu_cgspeed.bvh")
    i = src.index(b"Frame Time")
    i = src.index(b"\n", i) + 1
    m = read_bvh(_variant(tmp_path, src[:i] + src[i:].replace(b" ", b" \x0c", 5)))
    np.testing.assert_array_equal(m.rotations, ref.rotations)


def test_single_row_and_no_trailing_newline(tmp_path):
    src = (FIXTURES / "cmu_cgspeed.bvh").read_bytes()
    i = src.index(b"Frame Time")
    i = src.index(b"\n", i) + 1
    one = re.sub(rb"Frames:\s*\d+", b"Frames: 1", src[:i]) + src[i:].split(b"\n")[0]
    m = read_bvh(_variant(tmp_path, one))
    assert m.num_frames == 1


def test_zero_frames(tmp_path):
    src = (FIXTURES / "cmu_cgspeed.bvh").read_bytes()
    i = src.index(b"MOTION")
    m = read_bvh(_variant(tmp_path, src[:i] + b"MOTION\nFrames: 0\nFrame Time: 0.01\n"))
    assert m.num_frames == 0 and m.skeleton.num_joints == 38


# -- options ------------------------------------------------------------------------


def test_units_override():
    path = shared_file("cmu_12_01_walk.bvh")
    auto = read_bvh(path)
    cm = read_bvh(path, units="cm")
    flt = read_bvh(path, units=0.01)
    assert cm.units == "cm" and cm.unit_scale == 0.01 and not cm.meta["units_detected"]
    assert flt.units == "cm"
    np.testing.assert_allclose(cm.world_positions() * CMU_UNIT / 0.01, auto.world_positions(), atol=1e-9)
    custom = read_bvh(path, units=0.05)
    assert custom.units == "0.05 m" and custom.unit_scale == 0.05
    with pytest.raises(OptionError, match="unknown length unit"):
        read_bvh(path, units="furlong")
    with pytest.raises(OptionError, match="positive"):
        read_bvh(path, units=-1.0)


def test_up_override():
    path = FIXTURES / "optitrack_motive.bvh"
    y = read_bvh(path)
    z = read_bvh(path, up="z")
    assert z.file_up == "Z"
    # Read as Z-up, the file's axes are kept: world = file * scale.
    py, pz = y.world_positions(), z.world_positions()
    np.testing.assert_allclose(pz[..., 0], py[..., 0], atol=1e-12)
    np.testing.assert_allclose(pz[..., 1], py[..., 2], atol=1e-12)
    np.testing.assert_allclose(pz[..., 2], -py[..., 1], atol=1e-12)
    with pytest.raises(OptionError):
        read_bvh(path, up="X")


def _z_up_offsets_variant(tmp_path: Path) -> Path:
    """edge_cases.bvh with the Y and Z components of every OFFSET swapped: a rest pose (and,
    its rotations being small, a motion) that stands along Z."""
    src = (FIXTURES / "edge_cases.bvh").read_text()
    out = []
    for line in src.splitlines(keepends=True):
        s = line.strip()
        if s.startswith("OFFSET") or s.startswith("End Site {"):
            head, rest = line.split("OFFSET", 1)
            tail = ""
            if "}" in rest:
                rest, tail = rest.split("}", 1)
                tail = "}" + tail
            x, y, z = rest.split()[:3]
            line = f"{head}OFFSET {x} {z} {y} {tail}".rstrip() + "\n"
        out.append(line)
    return _variant(tmp_path, "".join(out).encode())


def test_z_up_file_is_detected(tmp_path):
    """A file whose rest pose and motion both stand along Z is read as Z-up (with a note
    naming the override), exactly as up='Z' reads it; up='Y' still forces Y-up."""
    p = _z_up_offsets_variant(tmp_path)
    with pytest.warns(PhysmocapWarning, match="read it as Z-up"):
        auto = read_bvh(p)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        z = read_bvh(p, up="Z")
        y = read_bvh(p, up="Y")
    assert auto.file_up == "Z" and y.file_up == "Y"
    np.testing.assert_array_equal(auto.rotations, z.rotations)
    np.testing.assert_array_equal(auto.translations, z.translations)
    np.testing.assert_array_equal(auto.skeleton.offsets, z.skeleton.offsets)


def _stick_figure(tmp_path: Path, root_x_deg: float) -> Path:
    """A Y-up file of a stick figure whose offsets stand along +Z (head up +Z, legs down -Z);
    every frame turns the root ``root_x_deg`` about X."""
    hier = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine { OFFSET 0 0 25 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head { OFFSET 0 0 30 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 0 20 } }
    JOINT LeftArm { OFFSET 18 0 25 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 0 -55 } }
    JOINT RightArm { OFFSET -18 0 25 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 0 -55 } }
  }
  JOINT LeftUpLeg { OFFSET 10 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftLeg { OFFSET 0 0 -45 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 0 -45 } } }
  JOINT RightUpLeg { OFFSET -10 0 0 CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT RightLeg { OFFSET 0 0 -45 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 0 -45 } } }
}
MOTION
Frames: 4
Frame Time: 0.033333
"""
    rows = []
    for f in range(4):
        vals = [3.0 * f, 0.0, 90.0, 0.0, root_x_deg, 0.0] + [2.0 * np.sin(f + k) for k in range(8 * 3)]
        rows.append(" ".join(f"{v:.4f}" for v in vals))
    p = tmp_path / "stick.bvh"
    p.write_text(hier + "\n".join(rows) + "\n")
    return p


def test_lying_rest_pose_of_a_standing_motion_stays_y_up(tmp_path):
    """A Y-up file whose rest pose lies along Z but whose motion stands along Y (the root turns
    the body up) stays Y-up, with a hint that up='Z' exists; the same figure unturned (standing
    along Z in the motion too) is read as Z-up."""
    standing = _stick_figure(tmp_path, root_x_deg=-90.0)
    with pytest.warns(PhysmocapWarning, match="up='Z'"):
        m = read_bvh(standing)
    assert m.file_up == "Y"
    pos = m.world_positions()
    assert np.ptp(pos[..., 2], axis=1).min() > 1.5 * np.ptp(pos[..., 1], axis=1).max()  # stands along world Z
    lying = _stick_figure(tmp_path, root_x_deg=0.0)
    with pytest.warns(PhysmocapWarning, match="read it as Z-up"):
        assert read_bvh(lying).file_up == "Z"


def test_z_up_file_with_a_root_wrapper_left_behind(tmp_path):
    """A Z-up file whose root wrapper stays at the origin while the body walks 4 m away (Bandai
    Namco's joint_Root): the wrapper is no part of the figure's size, so the walk still reads
    as standing along Z."""
    body = _stick_figure(tmp_path, root_x_deg=0.0).read_text()
    head, rows = body.split("Frame Time: 0.033333\n")
    head = head.replace("ROOT Hips\n{\n  OFFSET 0 0 0\n", "ROOT Root\n{\n  OFFSET 0 0 0\n"
                        "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
                        "  JOINT Hips {\n  OFFSET 0 0 0\n", 1)
    head = head.replace("\n}\nMOTION", "\n}\n}\nMOTION")
    head = head.replace("Frames: 4", "Frames: 40")
    lines = []
    for f in range(40):
        vals = [0.0] * 6 + [0.0, 10.0 * f, 90.0, 0.0, 0.0, 0.0] + [2.0 * np.sin(f + k) for k in range(8 * 3)]
        lines.append(" ".join(f"{v:.4f}" for v in vals))
    p = tmp_path / "wrapped.bvh"
    p.write_text(head + "Frame Time: 0.033333\n" + "\n".join(lines) + "\n")
    with pytest.warns(PhysmocapWarning, match="read it as Z-up"):
        m = read_bvh(p)
    assert m.file_up == "Z"


def test_retarget_in_up_option(tmp_path, monkeypatch):
    """retarget passes --in-up to the BVH reader as its up axis and refuses it on other inputs."""
    import physmocap.sources as sources
    from physmocap.cli import main
    from physmocap.errors import InputError

    seen = {}

    def fake_load(path, **opts):
        seen.update(opts)
        raise InputError("stop here", path=path)

    monkeypatch.setattr(sources, "load_motion", fake_load)
    p = _stick_figure(tmp_path, root_x_deg=0.0)
    assert main(["retarget", str(p), "-o", str(tmp_path / "o.bvh"), "--in-up", "y"]) == 2
    assert seen.get("up") == "Y"
    seen.clear()
    assert main(["retarget", str(tmp_path / "x.trc"), "-o", str(tmp_path / "o2.bvh"), "--in-up", "Z"]) == 2
    assert "up" not in seen
    seen.clear()  # the bundled clip is a BVH file ("--in-up: for BVH files only" before)
    assert main(["retarget", "example", "-o", str(tmp_path / "o3.bvh"), "--in-up", "Y"]) == 2
    assert seen.get("up") == "Y"


def test_detect_units_bounds():
    assert detect_units(1.8)[0] == "m"
    assert detect_units(30.0)[0] == "cmu"
    assert detect_units(67.0)[0] == "inch"
    assert detect_units(175.0)[0] == "cm"
    assert detect_units(1750.0)[0] == "mm"
    assert resolve_units("Inches") == ("inch", 0.0254)
    assert resolve_units("0.001") == ("mm", 0.001)
    assert resolve_units("cmu")[1] == pytest.approx((1 / 0.45) * 2.54 / 100)


def test_degenerate_skeleton_sizes_from_first_frame(tmp_path):
    """All offsets zero (everything in position channels): units come from frame 0."""
    text = (
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n"
        "JOINT b\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n"
        "End Site\n{\nOFFSET 0 0 0\n}\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.01\n"
        "0 900 0 0 -850 0\n0 910 0 0 -850 0\n"
    )
    m = read_bvh(_variant(tmp_path, text.encode()))
    assert m.meta["rest_extent"] == 850.0
    assert m.units == "mm"


def test_euler_to_quat_matches_scipy():
    """rotations.euler_to_quat (closed form, the reader's hot path) equals scipy's from_euler."""
    rng = np.random.default_rng(1)
    a = rng.uniform(-400, 400, (50, 4, 3))
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        q = euler_to_quat(a, order, degrees=True)
        ref = Rotation.from_euler(order, a.reshape(-1, 3), degrees=True).as_quat().reshape(q.shape)
        np.testing.assert_allclose(np.abs(np.sum(q * ref, axis=-1)), 1.0, atol=1e-12)
