"""Joint-position files: CSV (wide, long), NPZ, JSON lines; options and clear errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from physmocap.errors import InputError, OptionError
from physmocap.sources import load_motion
from physmocap.sources.positions import TRACKER_LAYOUTS, known_layout, positional_motion, read_positions
from physmocap.sources.sensor import guess_units, level_rotation, to_world, unit_scale

NITE = TRACKER_LAYOUTS["nite"]

# A standing NITE body in the camera frame (mirrored: X = performer's right, Y up,
# Z depth), millimetres, 2.5 m in front of a camera 1 m above the floor.
_BODY_M = {
    "head": (0.0, 1.65, 0.0), "neck": (0.0, 1.45, 0.0), "torso": (0.0, 1.20, 0.0),
    "left_shoulder": (-0.18, 1.42, 0.0), "right_shoulder": (0.18, 1.42, 0.0),
    "left_elbow": (-0.22, 1.15, 0.0), "right_elbow": (0.22, 1.15, 0.0),
    "left_hand": (-0.24, 0.90, 0.02), "right_hand": (0.24, 0.90, 0.02),
    "left_hip": (-0.10, 0.95, 0.0), "right_hip": (0.10, 0.95, 0.0),
    "left_knee": (-0.10, 0.52, -0.03), "right_knee": (0.10, 0.52, -0.03),
    "left_foot": (-0.10, 0.08, 0.0), "right_foot": (0.10, 0.08, 0.0),
}  # fmt: skip


def _standing(F: int = 20, seed: int = 0) -> np.ndarray:
    """(F, 15, 3) camera-frame mm; the performer faces the camera and sways a little."""
    rng = np.random.default_rng(seed)
    base = np.array([_BODY_M[n] for n in NITE]) * 1000.0
    base[:, 1] -= 1000.0  # camera 1 m above the floor
    base[:, 2] += 2500.0
    sway = 20.0 * np.sin(np.linspace(0, 2 * np.pi, F))[:, None, None] * np.array([1.0, 0.0, 0.0])
    return base[None] + sway + rng.normal(0, 1.0, (F, 15, 3))


def _write_wide_csv(path, pos, conf=None, fps=30.0, comments=True):
    cols = ["frame", "time"] + [f"{n}_{a}" for n in NITE for a in ("x", "y", "z", "conf")]
    lines = [f"# fps: {fps}", "# units: mm"] if comments else []
    lines.append(",".join(cols))
    for f in range(len(pos)):
        row = [str(f), repr(f / fps)]
        for j in range(15):
            vals = ["" if not np.isfinite(v) else repr(float(v)) for v in pos[f, j]]
            row += vals + [repr(1.0 if conf is None else float(conf[f, j]))]
        lines.append(",".join(row))
    path.write_text("\n".join(lines) + "\n")


def test_units_and_frames():
    assert unit_scale("mm") == ("mm", 0.001) and unit_scale("Millimetres")[1] == 0.001
    assert unit_scale(0.5) == ("0.5 m", 0.5)
    with pytest.raises(OptionError, match="unknown length unit"):
        unit_scale("furlong")
    pos = _standing()
    assert guess_units(pos) == "mm" and guess_units(pos / 10) == "cm" and guess_units(pos / 1000) == "m"
    # mirrored camera frame: depth +Z -> world -Y, Y up -> +Z, X kept
    np.testing.assert_allclose(to_world([1.0, 2.0, 3.0]), [1.0, -3.0, 2.0])
    np.testing.assert_allclose(to_world([1.0, 2.0, 3.0], mirrored=False), [-1.0, -3.0, 2.0])
    np.testing.assert_allclose(to_world([1.0, 2.0, 3.0], frame="world", up="Z"), [1.0, 2.0, 3.0])
    for v in ([0, 0.1, 1.0], [0.3, -0.2, 0.9], [0, 0, -1.0]):
        R = level_rotation(np.array(v))
        np.testing.assert_allclose(R @ (np.array(v) / np.linalg.norm(v)), [0, 0, 1], atol=1e-12)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_wide_csv_standing_body(tmp_path):
    path = tmp_path / "nite.csv"
    _write_wide_csv(path, _standing())
    m = read_positions(path)
    assert m.fps == 30.0 and m.units == "mm" and m.num_frames == 20
    assert not m.is_rotational and np.all(np.isfinite(m.positions))
    assert m.skeleton.names[0] == "pelvis" and m.skeleton.parents[0] == -1
    assert m.meta["tracker"]["synthesized"] == ["pelvis"]
    pos = {n: m.positions[:, m.skeleton.index(n)] for n in m.skeleton.names}
    # Z up, metres, floor at the feet (ankle height about 7 cm above it)
    assert np.all(pos["head"][:, 2] > pos["pelvis"][:, 2] + 0.5)
    assert 1.55 < np.median(pos["head"][:, 2]) < 1.75
    assert 0.03 < np.median(pos["left_foot"][:, 2]) < 0.1
    assert m.floor_height() == 0.0
    # the mapping used (with the synthesised pelvis) maps the motion for the retargeter
    from physmocap.sources.profiles import map_skeleton

    jm = map_skeleton(m, mapping=m.meta["source_mapping"])
    assert m.skeleton.names[jm.indices["pelvis"]] == "pelvis"
    assert m.skeleton.names[jm.indices["left_ankle"]] == "left_foot"
    # pelvis synthesised at the midpoint of the hips
    np.testing.assert_allclose(pos["pelvis"], 0.5 * (pos["left_hip"] + pos["right_hip"]), atol=1e-12)
    # right-handed body: facing the camera (world +Y after conversion), left is -X
    assert np.median(pos["left_hip"][:, 0] - pos["right_hip"][:, 0]) < 0
    # parents come before children and follow the canonical tree
    sk = m.skeleton
    assert sk.names[sk.parents[sk.index("left_knee")]] == "left_hip"
    assert sk.names[sk.parents[sk.index("neck")]] == "torso"


def test_long_csv_matches_wide(tmp_path):
    pos = _standing(8)
    wide = tmp_path / "w.csv"
    _write_wide_csv(wide, pos)
    long_ = tmp_path / "l.csv"
    rows = ["frame,joint,x,y,z,confidence"]
    for f in range(8):
        for j, n in enumerate(NITE):
            if (f, j) == (3, 5):
                continue  # a missing row is a missing sample
            rows.append(f"{f},{n},{float(pos[f, j, 0])!r},{float(pos[f, j, 1])!r},{float(pos[f, j, 2])!r},1")
    long_.write_text("\n".join(rows) + "\n")
    a = read_positions(wide)
    b = read_positions(long_, fps=30, units="mm")
    ok = b.confidence > 0
    assert not ok[3, b.skeleton.index(NITE[5])] or b.meta["gap_summary"]["runs"] == 1
    assert b.meta["gaps"] == [{"joint": NITE[5], "start": 3, "end": 3, "frames": 1, "action": "filled"}]
    assert a.skeleton.names == b.skeleton.names
    mask = np.ones(a.positions.shape[:2], dtype=bool)
    mask[3, a.skeleton.index(NITE[5])] = False
    np.testing.assert_allclose(a.positions[mask], b.positions[mask], atol=2e-3)


def test_npz_and_jsonl_match_csv(tmp_path):
    pos = _standing(10)
    pos[4, 0] = np.nan
    conf = np.ones((10, 15))
    conf[4, 0] = 0.0
    csv_path = tmp_path / "a.csv"
    _write_wide_csv(csv_path, pos, conf)
    npz_path = tmp_path / "a.npz"
    np.savez(npz_path, positions=pos, names=np.array(NITE), confidence=conf, fps=np.array(30.0))
    jl = tmp_path / "a.jsonl"
    lines = [json.dumps({"fps": 30, "units": "mm"})]
    for f in range(10):
        joints = {n: (None if not np.isfinite(pos[f, j]).all() else [*pos[f, j].tolist(), 1.0])
                  for j, n in enumerate(NITE)}  # fmt: skip
        lines.append(json.dumps({"frame": f, "joints": joints}))
    jl.write_text("\n".join(lines) + "\n")
    a, b, c = read_positions(csv_path), read_positions(npz_path), read_positions(jl)
    for other in (b, c):
        assert other.skeleton.names == a.skeleton.names
        np.testing.assert_allclose(other.positions, a.positions, atol=1e-9)
        np.testing.assert_allclose(other.confidence, a.confidence, atol=1e-12)
    assert a.meta["gaps"][0]["joint"] == "head" and a.meta["gaps"][0]["action"] == "filled"
    # the registry dispatches on the suffix
    assert load_motion(npz_path).skeleton.names == a.skeleton.names


def test_npz_without_names_uses_the_layout_by_count(tmp_path):
    p = tmp_path / "k.npz"
    np.savez(p, positions=_standing(5), fps=np.array(30.0))
    m = read_positions(p)
    assert set(NITE) <= set(m.skeleton.names)
    assert known_layout(25)[0] == "SpineBase" and known_layout(32)[0] == "PELVIS" and known_layout(7) is None


def test_times_column_places_frames_on_a_grid(tmp_path):
    pos = _standing(12)
    path = tmp_path / "t.csv"
    _write_wide_csv(path, pos, comments=False)
    text = path.read_text().splitlines()
    del text[1 + 6]  # frame 6 never arrived
    path.write_text("\n".join(text) + "\n")
    m = read_positions(path, units="mm")
    assert m.num_frames == 12 and m.fps == pytest.approx(30.0)
    assert any(g["joint"] == "*" and g["start"] == 6 for g in m.meta["gaps"])


def test_smoothing_reduces_jitter(tmp_path):
    rng = np.random.default_rng(5)
    pos = _standing(90) + rng.normal(0, 15.0, (90, 15, 3))
    path = tmp_path / "n.csv"
    _write_wide_csv(path, pos)
    raw = read_positions(path)
    smooth = read_positions(path, smooth={"min_cutoff": 1.0, "beta": 0.5})
    j = raw.skeleton.index("head")
    assert np.diff(smooth.positions[:, j], axis=0).std() < 0.5 * np.diff(raw.positions[:, j], axis=0).std()
    assert smooth.meta["tracker"]["smoothed"]


def test_given_floor_plane_and_world_frame(tmp_path):
    pos = _standing(10)
    path = tmp_path / "p.csv"
    _write_wide_csv(path, pos)
    # floor 1 m below the camera: y = -1000 mm  ->  0 x + 1 y + 0 z + 1000 = 0
    m = read_positions(path, floor_plane=(0, 1, 0, 1000))
    assert m.meta["tracker"]["ground"]["method"] == "given"
    head = m.positions[:, m.skeleton.index("head"), 2]
    np.testing.assert_allclose(np.median(head), 1.65, atol=0.01)
    # the same data already in a Y-up world in metres, no levelling or floor change
    w = positional_motion(NITE, pos / 1000.0, None, 30.0, "mem", frame="world", up="Y", units="m",
                          level=False, floor=None)  # fmt: skip
    np.testing.assert_allclose(w.positions[:, w.skeleton.index("head"), 2], pos[:, 0, 1] / 1000.0)


# --- errors: one clear message each -------------------------------------------------
@pytest.mark.parametrize(
    "text, match",
    [
        ("frame,head_x,head_y\n0,1,2\n", r"joint 'head' has columns head_x, head_y but no head_z"),
        ("frame,a,b\n0,1,2\n", "no joint columns"),
        ("# fps: 30\n", "expected a header row"),
        ("frame,head_x,head_y,head_z\n", "no data rows"),
        ("frame,head_x,head_y,head_z\n0,1,2\n", r":2: row has 3 cells"),
        ("frame,head_x,head_y,head_z\n0,1,abc,3\n", r":2: column 'head_y': 'abc' is not a number"),
        ("frame,joint,x,y\n0,head,1,2\n", "long CSV .* lacks column"),
        ("head_x,head_y,head_z\n1,2,3\n", "no frame rate"),
    ],
)
def test_csv_errors(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as e:
        read_positions(path)
    assert str(path) in str(e.value)


def test_npz_errors(tmp_path):
    p = tmp_path / "bad.npz"
    np.savez(p, pos=np.zeros((3, 15, 3)))
    with pytest.raises(InputError, match="no 'positions' array"):
        read_positions(p)
    np.savez(p, positions=np.zeros((3, 15)))
    with pytest.raises(InputError, match=r"\(F, J, 3\)"):
        read_positions(p)
    np.savez(p, positions=np.zeros((3, 15, 3)), names=np.array(NITE, dtype=object))
    with pytest.raises(InputError, match="Python objects"):
        read_positions(p, fps=30)
    np.savez(p, positions=np.zeros((3, 7, 3)))
    with pytest.raises(InputError, match="no 'names' array and 7 joints"):
        read_positions(p, fps=30)
    p.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a readable NPZ"):
        read_positions(p)


@pytest.mark.parametrize(
    "text, match",
    [
        ('{"fps": 30}\n{"joints": {"head": [1, 2]}}\n', r":2: joint 'head': expected \[x, y, z\]"),
        ('{"fps": 30}\n{"joints": {"head": {"x": 1, "y": 2}}}\n', r":2: joint 'head' lacks z"),
        ('{"fps": 30}\n{"joints": [1, 2, 3]}\n', r":2: 'joints' must be"),
        ('{"fps": 30}\n{"joints": {"head": [1, 2, 3]}\n', r":2: invalid JSON"),
        ('{"fps": 30}\n', "no frames"),
        ('{"fps": 30}\n{"joints": {"head": ["a", 2, 3]}}\n', r"'a' is not a number"),
    ],
)
def test_jsonl_errors(tmp_path, text, match):
    path = tmp_path / "bad.jsonl"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        read_positions(path)


def test_option_errors(tmp_path):
    path = tmp_path / "ok.csv"
    _write_wide_csv(path, _standing(5))
    with pytest.raises(OptionError, match="unknown option"):
        read_positions(path, colour="red")
    with pytest.raises(OptionError, match="mirrored must be true or false"):
        read_positions(path, mirrored="perhaps")
    with pytest.raises(OptionError, match="floor_plane"):
        read_positions(path, floor_plane=(0, 0, 0, 1))
    with pytest.raises(OptionError, match="min_confidence"):
        read_positions(path, min_confidence=2)


def test_cli_reports_missing_columns_in_one_line(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("frame,head_x,head_y\n0,1,2\n")
    r = subprocess.run([sys.executable, "-m", "physmocap", "convert", str(path), str(tmp_path / "o.mcap")],
                       capture_output=True, text=True)  # fmt: skip
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "no head_z" in r.stderr


def test_mapping_file_for_an_unknown_tracker(tmp_path):
    """Joint names no profile knows, mapped by a user mapping file."""
    pos = _standing(10)
    names = [f"p{k}" for k in range(15)]
    canon = {"head": "head", "neck": "neck", "torso": "chest", "left_shoulder": "left_shoulder",
             "right_shoulder": "right_shoulder", "left_elbow": "left_elbow", "right_elbow": "right_elbow",
             "left_hand": "left_wrist", "right_hand": "right_wrist", "left_hip": "left_hip",
             "right_hip": "right_hip", "left_knee": "left_knee", "right_knee": "right_knee",
             "left_foot": "left_ankle", "right_foot": "right_ankle"}  # fmt: skip
    lines = ['profile = "none"', "[joints]"] + [f'{canon[n]} = "p{k}"' for k, n in enumerate(NITE)]
    mapping = tmp_path / "tracker.map.toml"
    mapping.write_text("\n".join(lines) + "\n")
    npz = tmp_path / "t.npz"
    np.savez(npz, positions=pos, names=np.array(names), fps=np.array(30.0))
    m = read_positions(npz, mapping=str(mapping))
    assert m.meta["tracker"]["joint_map"]["left_ankle"] == "p13"
    sk = m.skeleton
    assert sk.names[sk.parents[sk.index("p11")]] == "p9"  # knee hangs from the hip
    head = m.positions[:, sk.index("p0"), 2]
    assert 1.55 < np.median(head) < 1.75  # levelled, floor from the mapped feet
    # without the mapping the names mean nothing: a warning, no hierarchy, no floor
    with pytest.warns(UserWarning) as rec:
        bare = read_positions(npz)
    msgs = [str(w.message) for w in rec]
    assert any("not recognised" in s for s in msgs) and any("no feet mapped" in s for s in msgs)
    assert set(bare.skeleton.parents.tolist()) == {-1} and "floor_z" not in bare.meta


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    hnp.arrays(bool, (12, 15), elements=st.booleans()),
    st.sampled_from([0.0, 0.1, 0.5]),
    st.booleans(),
)
def test_property_nothing_non_finite_reaches_the_motion(missing, max_gap, smooth):
    import warnings

    pos = _standing(12)
    pos[missing] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = positional_motion(NITE, pos, None, 30.0, "mem", units="mm", max_gap=max_gap, smooth=smooth)
    assert np.all(np.isfinite(m.positions)) and np.all(np.isfinite(m.confidence))
    assert np.all((m.confidence >= 0) & (m.confidence <= 1))
    assert np.all(np.isfinite(m.skeleton.offsets))
    # a joint is only ever tracked where it, or both neighbours of a short gap, were measured
    for j, name in enumerate(NITE):
        k = m.skeleton.index(name)
        if missing[:, j].all():
            assert np.all(m.confidence[:, k] == 0)
