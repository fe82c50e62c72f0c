"""Streaming marker solve (issue 11, item 5): marker MCAP, calibrate once, one frame at a time."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from conftest import shared_file
from physmocap.cli import main
from physmocap.markers.recording import MarkerRecording


def _cmu(frames: int) -> MarkerRecording:
    from physmocap.sources.c3d import read_c3d_markers

    rec = read_c3d_markers(shared_file("cmu_01_01_markers.c3d"))
    return MarkerRecording(rec.labels, rec.positions[:frames], rec.fps, rec.source)


def test_marker_mcap_round_trip_is_exact_and_deterministic(tmp_path):
    from physmocap.export.mcap import write_markers_mcap
    from physmocap.sources import load_motion
    from physmocap.sources.mcap import has_markers, read_mcap_markers

    rec = _cmu(240)
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_markers_mcap(rec, a)
    write_markers_mcap(rec, b)
    assert a.read_bytes() == b.read_bytes() and has_markers(a)
    back = read_mcap_markers(a)
    assert back.labels == rec.labels and back.fps == rec.fps
    assert np.array_equal(np.isnan(back.positions), np.isnan(rec.positions))
    assert np.array_equal(np.nan_to_num(back.positions), np.nan_to_num(rec.positions))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = load_motion(a, solve=False)  # the joint centres, as for the C3D itself
    assert m.num_frames == 240 and "left_knee" in m.skeleton.names


def test_convert_writes_markers_to_mcap(tmp_path, capsys):
    out = tmp_path / "take.mcap"
    c3d = shared_file("cmu_01_01_markers.c3d")
    assert main(["convert", str(c3d), str(out), "--start", "100", "--end", "220"]) == 0
    from physmocap.sources.mcap import read_mcap_markers

    assert read_mcap_markers(out).num_frames == 120
    assert main(["convert", str(c3d), str(tmp_path / "x.mcap"), "--fps", "60"]) == 2
    assert "do not apply" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()


def test_a_bad_marker_message_names_the_message(tmp_path):
    from mcap.writer import Writer

    from physmocap.errors import InputError
    from physmocap.sources.mcap import read_mcap_markers

    path = tmp_path / "m.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sch = w.register_schema("physmocap.LabelledPoints", "jsonschema", b"{}")
        ch = w.register_channel("/markers", "json", sch)
        for k, frame in enumerate((0, 1, -3)):
            msg = {"frame": frame, "frame_id": "world", "points": {"LKNE": {"x": 1.0, "y": 0.0, "z": 0.5}}}
            w.add_message(ch, log_time=k * 10_000_000, data=json.dumps(msg).encode(), publish_time=k * 10_000_000)
        w.finish()
    with pytest.raises(InputError, match="message 2 on /markers: field 'frame' must be a non-negative integer"):
        read_mcap_markers(path)
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(InputError, match="truncated MCAP file"):
        read_mcap_markers(path)


def test_the_stream_matches_the_offline_solve_and_is_fast():
    from physmocap.markers.solve import solve_markers
    from physmocap.markers.stream import MarkerStream, calibration_slice

    rec = _cmu(480)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stream = MarkerStream.calibrate(calibration_slice(rec, 2.0))
        frames = [stream.step(rec.positions[t]) for t in range(rec.num_frames)]
        offline = solve_markers(rec)
    rms = np.sqrt(np.nanmean(np.array([f.residual_rms for f in frames]) ** 2))
    assert rms < 0.012  # calibrated on 2 s only, solved causally
    assert offline.report()["overall"]["rms_mm"] < 12.0
    assert np.median(stream.latencies[1:]) < 0.005
    # a stream whose frames list the markers in another order, one missing
    order = list(reversed(rec.labels[1:]))
    s2 = MarkerStream(stream.actor, labels=tuple(order))
    col = [rec.labels.index(lab) for lab in order]
    f = s2.step(rec.positions[0][col])
    assert np.all(np.isfinite(f.qpos)) and f.residual_rms < 0.02
    with pytest.raises(Exception, match="a frame needs"):
        s2.step(rec.positions[0])


def test_replay_streams_a_marker_mcap_onto_the_robot(tmp_path, capsys):
    from physmocap.export.mcap import write_markers_mcap

    path = tmp_path / "take.mcap"
    write_markers_mcap(_cmu(360), path)
    stats, out = tmp_path / "stats.json", tmp_path / "robot.npz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["replay", str(path), "--calibration-seconds", "2", "--character", "robot", "-o", str(out),
                     "--stats", str(stats)]) == 0
    s = json.loads(stats.read_text())
    assert s["frames"] == 360 and s["marker_residual_rms_mm"] < 15.0 and s["cpu_ms"]["median"] < 10.0
    with np.load(out) as z:
        assert z["qpos"].shape[0] == 360 and np.all(np.isfinite(z["qpos"]))
    assert "replayed 360 frames" in capsys.readouterr().out


@pytest.mark.filterwarnings("ignore:.*joint centres from the anatomical regression")
@pytest.mark.filterwarnings("ignore:.*marker\\(s\\) belong to no segment")
def test_replay_warns_when_the_calibration_is_longer_than_the_recording(tmp_path, capsys):
    from physmocap.export.mcap import write_markers_mcap

    path = tmp_path / "short.mcap"
    write_markers_mcap(_cmu(240), path)
    with pytest.warns(UserWarning, match=r"short\.mcap: the recording lasts 2 s, less than the 100 s of "
                      "--calibration-seconds; the actor is calibrated on all of it"):
        assert main(["replay", str(path), "--calibration-seconds", "100"]) == 0
    assert "calibrated on first 240 frames" in capsys.readouterr().out
