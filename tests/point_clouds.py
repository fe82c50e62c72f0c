"""Marker recordings as Foxglove ``foxglove.PointCloud`` MCAP files (JSON encoding), for the
tests of the marker MCAP reader and of every command that takes a marker recording."""

from __future__ import annotations

import base64
import json

import numpy as np

from conftest import shared_file
from physmocap.markers.recording import MarkerRecording

#: Foxglove NumericType FLOAT32, FLOAT64, UINT16.
FLOAT32, FLOAT64, UINT16 = 7, 8, 3


def cmu_markers(frames: int) -> MarkerRecording:
    """The first ``frames`` frames of the shared CMU marker take (skipped where it is absent)."""
    from physmocap.sources.c3d import read_c3d_markers

    rec = read_c3d_markers(shared_file("cmu_01_01_markers.c3d"))
    return MarkerRecording(rec.labels, rec.positions[:frames], rec.fps, rec.source)


def cloud(points: np.ndarray, ids: np.ndarray | None = None, dtype: str = "<f4") -> dict:
    """A foxglove.PointCloud JSON message body for ``(N, 3)`` points: x, y, z (``dtype``) and
    a 2-byte padding field, plus a UINT16 ``id`` when ``ids`` are given."""
    size = np.dtype(dtype).itemsize
    kind = FLOAT32 if size == 4 else FLOAT64
    fields = [{"name": a, "offset": k * size, "type": kind} for k, a in enumerate("xyz")]
    stride = 3 * size + 2
    cols = [("x", dtype), ("y", dtype), ("z", dtype), ("pad", "<u2")]
    if ids is not None:
        fields.append({"name": "id", "offset": stride, "type": UINT16})
        cols.append(("id", "<u2"))
        stride += 2
    arr = np.zeros(len(points), dtype=np.dtype(cols))
    for k, a in enumerate("xyz"):
        arr[a] = points[:, k]
    if ids is not None:
        arr["id"] = ids
    assert arr.dtype.itemsize == stride
    return {"frame_id": "mocap", "point_stride": stride, "fields": fields,
            "data": base64.b64encode(arr.tobytes()).decode()}


def write_cloud_mcap(path, frames: list[dict], fps: float, labels=None, meta_record: bool = False,
                     stamps: list[int] | None = None) -> None:
    """Messages ``frames`` (PointCloud bodies) on /markers, stamped ``i / fps``; the labels in
    the channel metadata, or in a physmocap.markers metadata record."""
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sch = w.register_schema("foxglove.PointCloud", "jsonschema", b"{}")
        chan_meta = {"labels": json.dumps(list(labels))} if labels is not None and not meta_record else {}
        ch = w.register_channel("/markers", "json", sch, metadata=chan_meta)
        if labels is not None and meta_record:
            w.add_metadata("physmocap.markers", {"topic": "/markers", "labels": json.dumps(list(labels)),
                                                 "fps": repr(fps)})
        for i, body in enumerate(frames):
            t = stamps[i] if stamps is not None else int(round(i * 1e9 / fps))
            msg = dict(body, timestamp={"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000})
            w.add_message(ch, log_time=t, data=json.dumps(msg).encode(), publish_time=t, sequence=i)
        w.finish()


def write_recording_cloud(path, rec: MarkerRecording) -> None:
    """``rec`` as a point cloud MCAP: one float64 cloud per frame, a point per label (unseen
    markers at (0, 0, 0), which the reader takes for gaps), the labels and the frame rate in a
    physmocap.markers metadata record, so the MCAP reads back exactly as ``rec``."""
    frames = [cloud(np.nan_to_num(rec.positions[t]), dtype="<f8") for t in range(rec.num_frames)]
    write_cloud_mcap(path, frames, rec.fps, rec.labels, meta_record=True)
