"""Marker MCAPs beyond physmocap's own: ``foxglove.PointCloud`` channels (labels from metadata),
and repeated frames or timestamps refused (issue 11, deliverable 5)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from physmocap.errors import InputError
from point_clouds import cloud as _cloud, cmu_markers as _cmu, write_cloud_mcap, write_recording_cloud

def test_a_point_cloud_marker_mcap_reads_like_the_c3d(tmp_path):
    from physmocap.sources.mcap import has_markers, read_mcap_markers

    rec = _cmu(120)
    shift = np.array([0.5, -0.25, 0.0])
    path = tmp_path / "cloud.mcap"
    frames = []
    for t in range(rec.num_frames):
        body = _cloud(np.nan_to_num(rec.positions[t] - shift), dtype="<f8")  # unseen: (0, 0, 0)
        body["pose"] = {"position": dict(zip("xyz", shift.tolist())), "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}
        frames.append(body)
    write_cloud_mcap(path, frames, rec.fps, rec.labels)
    assert has_markers(path)
    back = read_mcap_markers(path)
    assert back.labels == rec.labels and abs(back.fps - rec.fps) < 1e-4 and back.num_frames == 120  # fps from ns stamps
    assert np.array_equal(np.isnan(back.positions), np.isnan(rec.positions))
    assert np.allclose(back.positions, rec.positions, atol=1e-9, equal_nan=True)


def test_physmocap_writes_markers_as_a_point_cloud_read_back_exactly(tmp_path):
    """``write_markers_pointcloud_mcap``: Foxglove PointCloud messages (float64, NaN where
    unseen), the labels in metadata; read back exactly, the same bytes every time."""
    from physmocap.export.mcap import write_markers_pointcloud_mcap
    from physmocap.markers.recording import MarkerRecording
    from physmocap.sources.mcap import read_mcap_markers

    rec = _cmu(90)
    rec = MarkerRecording(rec.labels, rec.positions, rec.fps, rec.source, first_frame=7)
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_markers_pointcloud_mcap(rec, a)
    write_markers_pointcloud_mcap(rec, b)
    assert a.read_bytes() == b.read_bytes()
    back = read_mcap_markers(a)
    assert back.labels == rec.labels and back.fps == rec.fps and back.first_frame == 7
    assert np.array_equal(back.positions, rec.positions, equal_nan=True) and np.isnan(rec.positions).any()


def test_point_cloud_ids_place_points_and_a_rotated_pose_is_applied(tmp_path):
    from physmocap.sources.mcap import read_mcap_markers

    labels = ["LKNE", "RKNE", "LANK"]
    X = np.array([[0.1, 0.2, 0.5], [0.1, -0.2, 0.5], [0.0, 0.2, 0.1]])
    turn = {"x": 0.0, "y": 0.0, "z": np.sin(np.pi / 4), "w": np.cos(np.pi / 4)}  # 90 degrees about z
    frames = [dict(_cloud(X[[2, 0]], ids=np.array([2, 0])), pose={"position": {"x": 1, "y": 0, "z": 0},
                                                                  "orientation": turn}),
              dict(_cloud(X, ids=np.arange(3)), pose={"position": {"x": 1, "y": 0, "z": 0}, "orientation": turn})]
    path = tmp_path / "ids.mcap"
    write_cloud_mcap(path, frames, 100.0, labels, meta_record=True)
    rec = read_mcap_markers(path)
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    want = X @ Rz.T + [1, 0, 0]
    assert rec.fps == 100.0 and rec.labels == tuple(labels)
    assert np.isnan(rec.positions[0, 1]).all() and np.allclose(rec.positions[0, [0, 2]], want[[0, 2]], atol=1e-6)
    assert np.allclose(rec.positions[1], want, atol=1e-6)


def test_a_point_cloud_without_labels_is_one_clear_error(tmp_path):
    from physmocap.sources.mcap import read_mcap_markers

    path = tmp_path / "nolabels.mcap"
    write_cloud_mcap(path, [_cloud(np.ones((3, 3)))] * 2, 100.0)
    with pytest.raises(InputError, match=r"nolabels\.mcap: /markers is a foxglove.PointCloud without marker labels"):
        read_mcap_markers(path)


@pytest.mark.parametrize("case,needle", [
    ("count", "message 1 on /markers: 2 points, but the labels name 3 markers"),
    ("stamp", "message 1 on /markers: timestamp 0.000000000 s again \\(message 0 has it too\\)"),
    ("base64", "message 1 on /markers: field 'data' must be the points' bytes in base64"),
    ("stride", "message 1 on /markers: field 'z' \\(offset 8, 4 bytes\\) runs past the point stride of 10 bytes"),
    ("type", "message 1 on /markers: field 'x': numeric type 9 is not one of Foxglove's 1-8"),
    ("frame_id", "message 1 on /markers: frame_id 'other' differs from 'mocap' of message 0"),
])
def test_bad_point_clouds_name_the_message(tmp_path, case, needle):
    from physmocap.sources.mcap import read_mcap_markers

    good = _cloud(np.ones((3, 3)))
    bad = dict(good)
    stamps = None
    if case == "count":
        bad = _cloud(np.ones((2, 3)))
    elif case == "stamp":
        stamps = [0, 0]
    elif case == "base64":
        bad["data"] = "not base64!"
    elif case == "stride":
        bad["point_stride"] = 10
    elif case == "type":
        bad["fields"] = [dict(bad["fields"][0], type=9)] + bad["fields"][1:]
    elif case == "frame_id":
        bad["frame_id"] = "other"
    path = tmp_path / f"{case}.mcap"
    write_cloud_mcap(path, [good, bad], 100.0, ["LKNE", "RKNE", "LANK"], stamps=stamps)
    with pytest.raises(InputError, match=needle):
        read_mcap_markers(path)


def test_a_repeated_frame_number_in_labelled_points_is_an_error(tmp_path):
    """It was read silently, the later message replacing the earlier."""
    from mcap.writer import Writer

    from physmocap.sources.mcap import read_mcap_markers

    path = tmp_path / "twice.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        ch = w.register_channel("/markers", "json", w.register_schema("physmocap.LabelledPoints", "jsonschema", b"{}"))
        for k, (frame, x) in enumerate(((0, 1.0), (1, 1.0), (1, 2.0))):
            msg = {"frame": frame, "points": {"LKNE": {"x": x, "y": 0.0, "z": 0.5}}}
            w.add_message(ch, log_time=k * 10_000_000, data=json.dumps(msg).encode(), publish_time=k * 10_000_000)
        w.finish()
    with pytest.raises(InputError, match=r"twice\.mcap: message 2 on /markers: frame 1 again \(message 1 holds it too\)"):
        read_mcap_markers(path)


def test_replay_streams_a_point_cloud_marker_mcap(tmp_path, capsys):
    from physmocap.cli import main

    path = tmp_path / "cloud.mcap"
    write_recording_cloud(path, _cmu(240))
    stats = tmp_path / "stats.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["replay", str(path), "--calibration-seconds", "2", "--stats", str(stats)]) == 0
    s = json.loads(stats.read_text())
    assert s["frames"] == 240 and s["marker_residual_rms_mm"] < 15.0
    assert "replayed 240 frames" in capsys.readouterr().out
