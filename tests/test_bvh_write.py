"""BVH writer: round trips on real files, options, continuity, atomicity, refusal."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_BVH, shared_file
from physmocap.errors import OptionError, OutputError, PhysmocapWarning
from physmocap.export import write_motion
from physmocap.export.bvh import write_bvh, write_bvh_channels
from physmocap.motion import Motion, Skeleton
from physmocap.rotations import euler_to_quat
from physmocap.sources.bvh import read_bvh

FIXTURES = Path(__file__).parent / "fixtures" / "bvh"
VENDOR_FILES = sorted(p.name for p in FIXTURES.glob("*.bvh"))


def _assert_same_world(a: Motion, b: Motion, tol_rel: float = 1e-6) -> None:
    """Every joint's (and end site's) world position agrees to tol_rel of the height."""
    assert a.skeleton.names == b.skeleton.names
    assert a.num_frames == b.num_frames
    pa, pb = a.world_positions(), b.world_positions()
    tol = tol_rel * a.skeleton.height()
    for j, name in enumerate(a.skeleton.names):
        err = np.abs(pa[:, j] - pb[:, j]).max() if a.num_frames else 0.0
        assert err <= tol, f"{name}: world position differs by {err:.3g} m (tolerance {tol:.3g} m)"


def _motion_rows(path: Path) -> list[str]:
    lines = path.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.strip().startswith("Frame Time"))
    return [ln for ln in lines[i + 1 :] if ln.strip()]


@pytest.mark.parametrize("name", SHARED_BVH)
def test_round_trip_shared_files(tmp_path, name):
    """Read -> write -> read reproduces every joint's world position to 1e-6 of the height."""
    src = read_bvh(shared_file(name))
    out = tmp_path / name
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysmocapWarning)
        write_bvh(src, out)
        back = read_bvh(out)
    _assert_same_world(src, back)
    # Same layout, units, axis, rate and frame count as the source file.
    assert back.meta["bvh_channels"] == src.meta["bvh_channels"]
    assert back.units == src.units and back.file_up == "Y"
    assert back.fps == pytest.approx(src.fps, rel=1e-9)
    rows = _motion_rows(out)
    assert len(rows) == src.num_frames
    assert f"Frames: {src.num_frames}" in out.read_text()


@pytest.mark.parametrize("name", VENDOR_FILES)
def test_round_trip_fixtures(tmp_path, name):
    src = read_bvh(FIXTURES / name)
    out = tmp_path / name
    write_bvh(src, out)
    back = read_bvh(out)
    _assert_same_world(src, back)
    assert back.meta["bvh_channels"] == src.meta["bvh_channels"]
    assert list(back.translated) == list(src.translated)


@pytest.mark.parametrize("order", ["XYZ", "YZX", "ZXY"])
def test_rotation_order_units_and_up(tmp_path, order):
    src = read_bvh(shared_file("cmu_12_01_walk.bvh"))
    out = tmp_path / "o.bvh"
    write_bvh(src, out, rotation_order=order, units="cm", up="Z", precision=7)
    back = read_bvh(out, units="cm", up="Z")
    _assert_same_world(src, back)
    chans = back.meta["bvh_channels"]
    assert chans["Hips"] == ["Xposition", "Yposition", "Zposition"] + [f"{a}rotation" for a in order]
    assert all(c[-3:] == [f"{a}rotation" for a in order] for c in chans.values())
    # Written in centimetres and Z-up: the hips stand about 0.9 m above the floor
    # along the file's third axis.
    first = np.array(_motion_rows(out)[0].split(), dtype=float)
    assert 50 < first[2] < 150


def test_units_as_float_and_name(tmp_path):
    src = read_bvh(FIXTURES / "optitrack_motive.bvh")
    write_bvh(src, tmp_path / "a.bvh", units=0.001)
    write_bvh(src, tmp_path / "b.bvh", units="mm")
    assert (tmp_path / "a.bvh").read_bytes() == (tmp_path / "b.bvh").read_bytes()
    assert read_bvh(tmp_path / "a.bvh").units == "mm"  # detected back from the size


def test_precision(tmp_path):
    src = read_bvh(FIXTURES / "cmu_cgspeed.bvh")
    write_bvh(src, tmp_path / "p2.bvh", precision=2)
    row = _motion_rows(tmp_path / "p2.bvh")[1].split()
    assert all(len(v.split(".")[1]) == 2 for v in row)
    write_bvh(src, tmp_path / "p0.bvh", precision=0)
    assert all("." not in v for v in _motion_rows(tmp_path / "p0.bvh")[1].split())
    for bad in (-1, 16, 2.5, True):
        with pytest.raises(OptionError):
            write_bvh(src, tmp_path / "x.bvh", precision=bad)


def test_no_negative_zero_and_deterministic(tmp_path):
    src = read_bvh(shared_file("optitrack_hops_crouch.bvh"))  # has "-0.000000" offsets
    write_bvh(src, tmp_path / "a.bvh")
    write_bvh(src, tmp_path / "b.bvh")
    text = (tmp_path / "a.bvh").read_text()
    assert " -0.000000" not in text and "\t-0.000000" not in text
    assert (tmp_path / "a.bvh").read_bytes() == (tmp_path / "b.bvh").read_bytes()


def test_euler_continuity(tmp_path):
    """A joint spinning many turns is written without 360-degree jumps, and
    through gimbal-lock-adjacent poses without 180-degree branch flips."""
    F = 400
    t = np.linspace(0.0, 1.0, F)
    yaw = 3 * 360.0 * t  # three full turns
    pitch = 89.0 * np.sin(2 * np.pi * t)  # passes near the ZXY middle-axis lock
    angles = np.stack([yaw, pitch, 30.0 * np.cos(6 * np.pi * t)], axis=-1)
    q = euler_to_quat(angles, "ZXY", degrees=True)
    sk = Skeleton(("root", "tip"), np.array([-1, 0]), np.array([[0, 0, 1.0], [0, 0.5, 0]]), np.array([False, True]))
    rot = np.zeros((F, 2, 4))
    rot[:, 0] = q
    rot[:, 1, 3] = 1.0
    m = Motion(sk, 100.0, rotations=rot, translations=np.zeros((F, 1, 3)) + [0, 0, 1.0], translated=[0])
    for order in ("ZXY", "XYZ", "YZX"):
        out = tmp_path / f"spin_{order}.bvh"
        write_bvh(m, out, rotation_order=order, up="Z", units="m")
        vals = np.array([r.split() for r in _motion_rows(out)], dtype=float)[:, 3:]
        # No 180/360-degree jumps (near a gimbal lock of the chosen order the
        # angles legitimately move fast, but not by half a turn).
        assert np.abs(np.diff(vals, axis=0)).max() < 90.0, order
        if order == "ZXY":  # the generating order: the very same angles come back
            np.testing.assert_allclose(vals, angles, atol=1e-5)
        back = read_bvh(out, units="m", up="Z")
        np.testing.assert_allclose(back.world_positions(), m.world_positions(), atol=1e-6)
    # The yaw accumulates past 360 instead of wrapping.
    vals = np.array([r.split() for r in _motion_rows(tmp_path / "spin_ZXY.bvh")], dtype=float)
    assert vals[-1, 3] > 1000.0


def test_layout_widened_when_needed(tmp_path):
    """A source layout that cannot hold the motion gets the missing channels, with a warning."""
    src = read_bvh(FIXTURES / "edge_cases.bvh")
    # Writing Z-up moves Hand's animated Yposition onto the file's Z axis.
    with pytest.warns(PhysmocapWarning, match="Hand"):
        write_bvh(src, tmp_path / "z.bvh", up="Z")
    back = read_bvh(tmp_path / "z.bvh", up="Z")
    _assert_same_world(src, back)
    # A 1-axis joint given an extra rotation about another axis.
    rot = src.rotations.copy()
    ref = src.skeleton.index("Reference")
    rot[:, ref] = euler_to_quat(np.tile([[10.0, 20.0, 5.0]], (src.num_frames, 1)), "ZXY", degrees=True)
    m = src.replace(rotations=rot)
    with pytest.warns(PhysmocapWarning, match="Reference"):
        write_bvh(m, tmp_path / "w.bvh")
    back = read_bvh(tmp_path / "w.bvh")
    assert len(back.meta["bvh_channels"]["Reference"]) == 3
    _assert_same_world(m, back)


def test_motion_without_meta_gets_default_layout(tmp_path):
    src = read_bvh(FIXTURES / "daz_poser.bvh")
    bare = src.replace(meta={}, units="m", unit_scale=1.0, file_up="Z")
    write_bvh(bare, tmp_path / "d.bvh")
    back = read_bvh(tmp_path / "d.bvh", units="m")
    assert back.file_up == "Y"  # BVH convention for motions not read from a BVH file
    assert back.meta["bvh_channels"]["hip"] == [
        "Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"
    ]
    _assert_same_world(src, back)


def test_refuses_non_finite_and_positional(tmp_path):
    src = read_bvh(FIXTURES / "cmu_cgspeed.bvh")
    rot = src.rotations.copy()
    rot[3, src.skeleton.index("LeftLeg"), 0] = np.nan
    out = tmp_path / "bad.bvh"
    with pytest.raises(OutputError, match=r"frame 3: rotation of joint 'LeftLeg' is not finite"):
        write_bvh(src.replace(rotations=rot), out)
    assert not out.exists()
    tra = src.translations.copy()
    tra[1, 0, 2] = np.inf
    with pytest.raises(OutputError, match="translation of joint 'Hips'"):
        write_bvh(src.replace(translations=tra), out)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary files left behind
    pos = Motion(src.skeleton, 30.0, positions=np.zeros((2, src.skeleton.num_joints, 3)))
    with pytest.raises(OptionError, match="positions only"):
        write_bvh(pos, out)
    with pytest.raises(OptionError):
        write_bvh(src, out, rotation_order="XXY")
    with pytest.raises(OptionError):
        write_bvh(src, out, up="X")
    with pytest.raises(OptionError):
        write_bvh(src, out, units="parsec")


def test_failed_write_keeps_existing_file(tmp_path):
    src = read_bvh(FIXTURES / "cmu_cgspeed.bvh")
    out = tmp_path / "keep.bvh"
    out.write_text("original")
    rot = src.rotations.copy()
    rot[-1, -2] = np.nan
    with pytest.raises(OutputError):
        write_bvh(src.replace(rotations=rot), out)
    assert out.read_text() == "original"
    assert sorted(os.listdir(tmp_path)) == ["keep.bvh"]


def test_write_motion_registry(tmp_path):
    src = read_bvh(FIXTURES / "mixamo.bvh")
    out = write_motion(src, tmp_path / "m.BVH", precision=5)
    back = read_bvh(out)
    _assert_same_world(src, back, tol_rel=1e-5)


def test_zero_frames_round_trip(tmp_path):
    src = read_bvh(FIXTURES / "cmu_cgspeed.bvh").slice_frames(0, 1)
    empty = src.replace(rotations=src.rotations[:0], translations=src.translations[:0])
    write_bvh(empty, tmp_path / "e.bvh")
    assert "Frames: 0" in (tmp_path / "e.bvh").read_text()
    assert read_bvh(tmp_path / "e.bvh").num_frames == 0


# -- the lower-level writer ----------------------------------------------------------


def test_write_bvh_channels_precomputed(tmp_path):
    """Joint order that is not depth-first: columns are reordered to the hierarchy."""
    names = ["pelvis", "spine", "thigh", "head", "head_End"]
    parents = [-1, 0, 0, 1, 3]
    offsets = np.array([[0, 90, 0], [0, 10, 0], [10, -5, 0], [0, 50, 0], [0, 20, 0]], dtype=float)
    end = [False, False, False, False, True]
    channels = [
        ["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"],
        ["Zrotation", "Xrotation", "Yrotation"],
        ["Xrotation"],
        ["Yrotation", "Xrotation"],
        [],
    ]
    data = np.array([
        [1, 90, 2, 0, 0, 0, 10, 0, 0, 45, 30, 5],
        [2, 91, 3, 5, 0, 0, 20, 0, 0, 40, 31, 6],
    ], dtype=float)
    out = write_bvh_channels(tmp_path / "c.bvh", names, parents, offsets, end, channels, data, 1 / 30, precision=3)
    text = out.read_text()
    # Depth-first: pelvis, spine, head, End Site, then thigh.
    order = [ln.split()[1] for ln in text.splitlines() if ln.strip().startswith(("ROOT", "JOINT"))]
    assert order == ["pelvis", "spine", "head", "thigh"]
    rows = _motion_rows(out)
    assert rows[0].split() == [
        "1.000", "90.000", "2.000", "0.000", "0.000", "0.000",  # pelvis
        "10.000", "0.000", "0.000",  # spine
        "30.000", "5.000",  # head
        "45.000",  # thigh
    ]
    m = read_bvh(out, units="cm")
    assert m.skeleton.names == ("pelvis", "spine", "head", "head_End", "thigh")
    assert m.fps == pytest.approx(30.0)


def test_write_bvh_channels_validates(tmp_path):
    args = dict(names=["a"], parents=[-1], offsets=np.zeros((1, 3)), end_site=[False],
                channels=[["Xrotation"]], frame_time=0.01)
    with pytest.raises(OutputError, match="not finite"):
        write_bvh_channels(tmp_path / "x.bvh", data=np.array([[np.nan]]), **args)
    with pytest.raises(ValueError):
        write_bvh_channels(tmp_path / "x.bvh", data=np.zeros((2, 2)), **args)
    with pytest.raises(OutputError, match="cannot be written"):
        write_bvh_channels(tmp_path / "x.bvh", data=np.zeros((1, 1)), **{**args, "names": ["a{b"]})
    assert not (tmp_path / "x.bvh").exists()


def test_block_boundaries_do_not_change_the_output(tmp_path, monkeypatch):
    """Frames are converted in blocks; tiny blocks give byte-identical files
    (Euler continuity and 1-2 axis joints carried across blocks)."""
    import physmocap.export.bvh as writer

    for name, kw in (("edge_cases.bvh", {}), ("cmu_cgspeed.bvh", {"rotation_order": "XYZ"})):
        src = read_bvh(FIXTURES / name)
        # Make the motion long and spinning so continuity matters.
        rot = np.concatenate([src.rotations] * 40)
        spin = euler_to_quat(np.stack([np.linspace(0, 2000, len(rot)), np.zeros(len(rot)), np.zeros(len(rot))], -1),
                             "YXZ", degrees=True)
        rot[:, 0] = spin
        m = src.replace(rotations=rot, translations=np.concatenate([src.translations] * 40))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PhysmocapWarning)
            write_bvh(m, tmp_path / "big.bvh", **kw)
            monkeypatch.setattr(writer, "_ROWS_PER_BLOCK", 7)
            write_bvh(m, tmp_path / "small.bvh", **kw)
            monkeypatch.undo()
        assert (tmp_path / "big.bvh").read_bytes() == (tmp_path / "small.bvh").read_bytes(), name


def _unwrap_reference(a: np.ndarray, order: str, degrees: bool) -> np.ndarray:
    """The per-frame definition of rotations.unwrap_euler (closest of the two
    Euler solutions to the previous frame, then whole turns)."""
    a = np.array(a, dtype=float)
    full = 360.0 if degrees else 2 * np.pi
    half = full / 2
    for t in range(1, len(a)):
        prev, cand = a[t - 1], a[t]
        best = cand + np.round((prev - cand) / full) * full
        alt = cand.copy()
        alt[..., 0] += half
        alt[..., 1] = half - alt[..., 1] if len(set(order)) == 3 else -alt[..., 1]
        alt[..., 2] += half
        alt = alt + np.round((prev - alt) / full) * full
        d_best = np.abs(best - prev).sum(-1)
        d_alt = np.abs(alt - prev).sum(-1)
        a[t] = np.where((d_alt < d_best)[..., None], alt, best)
    return a


def test_vectorised_unwrap_matches_per_frame_definition():
    from physmocap.rotations import quat_to_euler, unwrap_euler

    rng = np.random.default_rng(7)
    for trial in range(60):
        F = int(rng.integers(1, 50))
        shape = (F,) + tuple(int(x) for x in rng.integers(1, 4, size=int(rng.integers(0, 3)))) + (3,)
        degrees = bool(trial % 2)
        full = 360.0 if degrees else 2 * np.pi
        if trial % 3:
            a = np.cumsum(rng.normal(0, 0.3, size=shape) * full, axis=0)
        else:
            a = rng.uniform(-full, full, size=shape)
        order = ["ZXY", "XYZ", "ZXZ", "YZY"][trial % 4]
        np.testing.assert_allclose(unwrap_euler(a, order, degrees), _unwrap_reference(a, order, degrees), atol=1e-9)
    m = read_bvh(shared_file("cmu_01_01_jumps.bvh"))
    e = quat_to_euler(m.rotations, "ZXY", degrees=True)
    np.testing.assert_array_equal(unwrap_euler(e, "ZXY", True), _unwrap_reference(e, "ZXY", True))
