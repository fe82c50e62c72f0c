"""A NITE 15-joint stream made from the real CMU walk: read into the right world.

The stream (physmocap.sources.synth) has the NITE joints of the BVH, seen by a
camera a few metres in front of the walker, in camera millimetres, with noise,
dropouts and lost frames.  Reading it must give metres, Z up, the floor at the
feet, the walker's joints where they were (up to the unknown camera heading),
no non-finite numbers, and the gaps listed.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import shared_file
from physmocap.sources import load_motion
from physmocap.sources.positions import read_positions
from physmocap.sources.sensor import to_world
from physmocap.sources.synth import tracker_stream, write_stream_csv, write_stream_jsonl, write_stream_npz

WRITERS = {".csv": write_stream_csv, ".npz": write_stream_npz, ".jsonl": write_stream_jsonl}


@pytest.fixture(scope="module")
def walk():
    return load_motion(shared_file("cmu_12_01_walk.bvh"))


@pytest.fixture(scope="module")
def stream(walk):
    return tracker_stream(walk, camera_pitch_deg=12.0, camera_yaw_deg=20.0, seed=3)


def _align_xy(P: np.ndarray, T: np.ndarray) -> float:
    """RMS horizontal residual after the best rotation about Z and translation (no reflection)."""
    a, b = P[:, :2] - P[:, :2].mean(0), T[:, :2] - T[:, :2].mean(0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    R = (U @ Vt).T
    assert np.linalg.det(R) > 0, "the stream came back mirrored"
    return float(np.sqrt(((a @ R.T - b) ** 2).sum(1).mean()))


@pytest.mark.parametrize("suffix", sorted(WRITERS))
def test_stream_reads_into_the_right_world(stream, tmp_path, suffix):
    path = WRITERS[suffix](stream, tmp_path / f"nite{suffix}")
    m = read_positions(path)
    assert m.units == "mm" and m.fps == 30.0 and m.num_frames == stream.num_frames
    assert np.all(np.isfinite(m.positions)) and np.all(np.isfinite(m.confidence))
    idx = [m.skeleton.index(n) for n in stream.names]
    P, T = m.positions[:, idx], stream.truth
    ok = m.confidence[:, idx] > 0
    # up axis: within 1.5 degrees of the BVH's vertical (the capture floor itself
    # slopes about 0.5 degrees along this walk; the estimate follows the feet)
    g = m.meta["tracker"]["ground"]
    true_up = to_world(stream.camera_axes.T @ np.array([0.0, 0.0, 1.0]))
    assert np.degrees(np.arccos(np.dot(true_up, g["up"]))) < 1.5
    # heights: metres above the floor, within noise and the foot-height model
    dz = (P[..., 2] - T[..., 2])[ok]
    assert abs(np.median(dz)) < 0.03 and np.percentile(np.abs(dz), 95) < 0.08
    # floor at the feet: stance ankles a few centimetres up, nothing far below 0
    feet = [m.skeleton.index("left_foot"), m.skeleton.index("right_foot")]
    lowest = m.positions[:, feet, 2].min(axis=1)
    assert 0.03 < np.percentile(lowest, 10) < 0.1 and lowest.min() > -0.05
    assert m.floor_height() == 0.0
    # horizontal layout: the walk up to the camera's unknown heading
    assert _align_xy(P[ok], T[ok]) < 0.03
    # the walker covered the same ground (about 3.8 m) as in the BVH
    pelvis = m.positions[:, m.skeleton.index("pelvis")]
    hips = [stream.names.index("left_hip"), stream.names.index("right_hip")]
    truth_pelvis = stream.truth[:, hips].mean(axis=1)
    travel = np.linalg.norm(truth_pelvis[-1, :2] - truth_pelvis[0, :2])
    assert travel > 3.0
    assert abs(np.linalg.norm(pelvis[-1, :2] - pelvis[0, :2]) - travel) < 0.05


def test_gaps_are_handled_and_listed(stream, tmp_path):
    m = read_positions(write_stream_npz(stream, tmp_path / "n.npz"))
    gaps = m.meta["gaps"]
    lost = [g for g in gaps if g["joint"] == "*"]
    assert len(lost) == len(stream.events["lost"])
    for name, start, end in stream.events["dropouts"]:
        assert any(g["joint"] == name and g["start"] <= start and g["end"] >= end for g in gaps), name
    long_ones = [g for g in gaps if g["joint"] != "*" and g["frames"] > m.meta["tracker"]["max_gap_frames"]]
    assert long_ones and all(g["action"] == "masked" for g in long_ones)
    for g in long_ones:
        j = m.skeleton.index(g["joint"])
        assert np.all(m.confidence[g["start"] : g["end"] + 1, j] == 0.0)
    assert m.meta["gap_summary"]["lost_frames"] == sum(e - s + 1 for s, e in stream.events["lost"])


def test_unmirrored_stream_gives_the_same_motion(walk, tmp_path):
    a = tracker_stream(walk, mirrored=True, seed=1)
    b = tracker_stream(walk, mirrored=False, seed=1)
    ma = read_positions(write_stream_csv(a, tmp_path / "a.csv"))
    mb = read_positions(write_stream_csv(b, tmp_path / "b.csv"))
    assert mb.meta["tracker"]["mirrored"] is False
    np.testing.assert_allclose(ma.positions, mb.positions, atol=1e-9)
    # reading it with the wrong convention mirrors the body (and is detectably wrong)
    wrong = read_positions(tmp_path / "b.csv", mirrored=True)
    idx = [wrong.skeleton.index(n) for n in a.names]
    with pytest.raises(AssertionError, match="mirrored"):
        _align_xy(wrong.positions[:, idx].reshape(-1, 3), a.truth.reshape(-1, 3))


def test_given_floor_plane_matches_the_estimate(stream, tmp_path):
    path = write_stream_csv(stream, tmp_path / "n.csv")
    est = read_positions(path)
    given = read_positions(path, floor_plane=stream.floor_plane(), foot_height=0.0)
    assert given.meta["tracker"]["ground"]["method"] == "given"
    # the given plane is the BVH's floor exactly: heights match the truth up to noise
    idx = [given.skeleton.index(n) for n in stream.names]
    ok = given.confidence[:, idx] > 0
    dz = (given.positions[:, idx, 2] - stream.truth[..., 2])[ok]
    assert abs(np.median(dz)) < 0.005
    assert np.abs(np.median(est.positions[..., 2] - given.positions[..., 2])) < 0.03


def test_kinect_v2_stream_in_metres(walk, tmp_path):
    """The 25-joint Kinect v2 layout (metres, has its own pelvis): no synthesis needed."""
    s = tracker_stream(walk, layout="kinect_v2", units="m", seed=4)
    m = read_positions(write_stream_jsonl(s, tmp_path / "k.jsonl"))
    assert m.units == "m" and m.meta["tracker"]["synthesized"] == []
    assert m.skeleton.names[0] == "SpineBase" and m.meta["tracker"]["joint_map"]["left_toe"] == "FootLeft"
    idx = [m.skeleton.index(n) for n in s.names]
    ok = m.confidence[:, idx] > 0
    dz = (m.positions[:, idx, 2] - s.truth[..., 2])[ok]
    assert abs(np.median(dz)) < 0.04
    assert _align_xy(m.positions[:, idx][ok], s.truth[ok]) < 0.03
