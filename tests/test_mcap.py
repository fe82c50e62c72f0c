"""MCAP: BVH -> MCAP -> Motion round trips, schema validation, foreign layouts, bad files."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from conftest import shared_file
from physmocap.errors import InputError, OptionError, OutputError
from physmocap.export.mcap import (
    FRAME_TRANSFORMS_SCHEMA,
    JOINT_POSITIONS_SCHEMA,
    POSES_IN_FRAME_SCHEMA,
    track_from_motion,
    track_from_world_poses,
    write_motion_mcap,
    write_transforms_mcap,
)
from physmocap.motion import Motion, Skeleton
from physmocap.rotations import Rotation
from physmocap.sources import load_motion
from physmocap.sources.mcap import list_skeletons, read_mcap

# --- Foxglove's published JSON schemas (foxglove/schemas, schemas/jsonschema/*.json),
# --- transcribed for comparison; the files must declare exactly these structures.
_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}
_VEC3 = {"title": "foxglove.Vector3", "type": "object",
         "properties": {a: {"type": "number"} for a in "xyz"}}  # fmt: skip
_QUAT = {"title": "foxglove.Quaternion", "type": "object",
         "properties": {a: {"type": "number"} for a in "xyzw"}}  # fmt: skip
FOXGLOVE_FRAME_TRANSFORMS = {
    "title": "foxglove.FrameTransforms",
    "type": "object",
    "properties": {
        "transforms": {
            "type": "array",
            "items": {
                "title": "foxglove.FrameTransform",
                "type": "object",
                "properties": {
                    "timestamp": _TIME,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": _VEC3,
                    "rotation": _QUAT,
                },
            },
        }
    },
}
FOXGLOVE_POSES_IN_FRAME = {
    "title": "foxglove.PosesInFrame",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "poses": {
            "type": "array",
            "items": {
                "title": "foxglove.Pose",
                "type": "object",
                "properties": {"position": _VEC3, "orientation": _QUAT},
            },
        },
    },
}


def _structure(schema):
    """The schema without human-readable descriptions and comments."""
    if isinstance(schema, dict):
        return {k: _structure(v) for k, v in schema.items() if k not in ("description", "$comment")}
    if isinstance(schema, list):
        return [_structure(v) for v in schema]
    return schema


def _strict(schema):
    """Every declared property required and nothing else allowed (for stronger checks)."""
    s = copy.deepcopy(schema)

    def walk(node):
        if isinstance(node, dict):
            if node.get("type") == "object" and "properties" in node:
                node.setdefault("required", sorted(node["properties"]))
                node.setdefault("additionalProperties", False)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(s)
    return s


def test_schemas_are_foxgloves():
    assert _structure(FRAME_TRANSFORMS_SCHEMA) == FOXGLOVE_FRAME_TRANSFORMS
    assert _structure(POSES_IN_FRAME_SCHEMA) == FOXGLOVE_POSES_IN_FRAME
    for s in (FRAME_TRANSFORMS_SCHEMA, POSES_IN_FRAME_SCHEMA, JOINT_POSITIONS_SCHEMA):
        jsonschema.Draft7Validator.check_schema(s)


@pytest.fixture(scope="module")
def walk() -> Motion:
    return load_motion(shared_file("cmu_12_01_walk.bvh"))


def _assert_same_motion(a: Motion, b: Motion, tol: float = 1e-6) -> None:
    assert a.skeleton.names == b.skeleton.names
    np.testing.assert_array_equal(a.skeleton.parents, b.skeleton.parents)
    np.testing.assert_allclose(a.skeleton.offsets, b.skeleton.offsets, atol=tol)
    assert a.fps == b.fps and a.num_frames == b.num_frames
    pa, pb = a.world_positions(), b.world_positions()
    assert np.abs(pa - pb).max() <= tol


def test_bvh_round_trip_reproduces_positions(shared_bvh, tmp_path):
    m = load_motion(shared_bvh)
    if m.num_frames > 600:
        m = m.slice_frames(0, 600)
    out = tmp_path / "clip.mcap"
    write_motion_mcap(m, out)
    back = read_mcap(out)
    _assert_same_motion(m, back, tol=1e-6)
    # local rotations and translations come back exactly (floats written with repr)
    np.testing.assert_array_equal(back.rotations, m.rotations)
    np.testing.assert_array_equal(back.translated, m.translated)
    assert back.units == m.units and back.file_up == m.file_up and back.unit_scale == m.unit_scale
    assert back.meta["mcap"]["topic_prefix"] == "/skeleton"


def test_every_message_validates_against_its_schema(walk, tmp_path):
    m = walk.slice_frames(0, 40)
    out = tmp_path / "walk.mcap"
    write_motion_mcap(m, out, poses=True)
    seen = {}
    with open(out, "rb") as fh:
        reader = make_reader(fh)
        header = reader.get_header()
        assert header.library.startswith("physmocap ")
        summary = reader.get_summary()
        assert summary is not None
        assert {c.message_encoding for c in summary.channels.values()} == {"json"}
        assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
        validators: dict = {}
        for schema, channel, message in reader.iter_messages():
            if schema.id not in validators:
                declared = json.loads(schema.data)
                jsonschema.Draft7Validator.check_schema(declared)
                checks = [jsonschema.Draft7Validator(declared)]
                if schema.name.startswith("foxglove."):
                    ref = FOXGLOVE_FRAME_TRANSFORMS if "Transforms" in schema.name else FOXGLOVE_POSES_IN_FRAME
                    assert _structure(declared) == ref
                    checks.append(jsonschema.Draft7Validator(_strict(ref)))
                validators[schema.id] = checks
            obj = json.loads(message.data)
            for v in validators[schema.id]:
                v.validate(obj)
            seen.setdefault(channel.topic, (schema.name, 0))
            seen[channel.topic] = (schema.name, seen[channel.topic][1] + 1)
        metas = list(reader.iter_metadata())
    # the validators do reject what Foxglove would not read
    tf_checks = next(v for v in validators.values() if v[0].schema["title"] == "foxglove.FrameTransforms")
    for bad in ({"transforms": [{"translation": {"x": "1"}}]}, {"transforms": {}}):
        with pytest.raises(jsonschema.ValidationError):
            tf_checks[0].validate(bad)
    assert seen == {
        "/skeleton/tf": ("foxglove.FrameTransforms", 40),
        "/skeleton/joints": ("physmocap.JointPositions", 40),
        "/skeleton/poses": ("foxglove.PosesInFrame", 40),
    }
    assert [md.name for md in metas] == ["physmocap.skeleton"]
    meta = metas[0].metadata
    assert meta["units"] == "m" and meta["up_axis"] == "Z" and float(meta["fps"]) == m.fps
    assert json.loads(meta["joints"]) == list(m.skeleton.names)


def test_transforms_are_parent_to_child_and_reproduce_fk(walk, tmp_path):
    m = walk.slice_frames(100, 103)
    out = tmp_path / "walk.mcap"
    write_motion_mcap(m, out)
    with open(out, "rb") as fh:
        msgs = [json.loads(msg.data) for _, ch, msg in make_reader(fh).iter_messages(topics=["/skeleton/tf"])]
    pos = m.world_positions()
    tr = msgs[1]["transforms"]
    assert len(tr) == m.skeleton.num_joints
    world = {"world": (np.zeros(3), Rotation.identity())}
    for t in tr:
        p, r = world[t["parent_frame_id"]]
        v = np.array([t["translation"][a] for a in "xyz"])
        q = Rotation.from_quat([t["rotation"][a] for a in "xyzw"])
        world[t["child_frame_id"]] = (p + r.apply(v), r * q)
    got = np.array([world[f"skeleton/{n}"][0] for n in m.skeleton.names])
    np.testing.assert_allclose(got, pos[1], atol=1e-12)
    assert tr[0]["timestamp"] == {"sec": 0, "nsec": round(1e9 / m.fps)}


def test_output_is_deterministic(walk, tmp_path):
    m = walk.slice_frames(0, 50)
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_motion_mcap(m, a)
    write_motion_mcap(m, b)
    assert a.read_bytes() == b.read_bytes()


def test_positional_round_trip_keeps_confidence(tmp_path):
    rng = np.random.default_rng(0)
    sk = Skeleton(names=("pelvis", "left_hip", "right_hip"), parents=[-1, 0, 0],
                  offsets=[[0, 0, 1], [0, 0.1, 0], [0, -0.1, 0]])  # fmt: skip
    pos = rng.normal(size=(12, 3, 3))
    conf = rng.uniform(0, 1, size=(12, 3))
    conf[3, 1] = 0.0
    m = Motion(sk, 30.0, positions=pos, confidence=conf, meta={"gaps": [{"joint": "left_hip"}]})
    out = tmp_path / "pos.mcap"
    write_motion_mcap(m, out)
    back = read_mcap(out)
    assert not back.is_rotational
    np.testing.assert_array_equal(back.positions, pos)
    np.testing.assert_array_equal(back.confidence, conf)
    assert back.meta["gaps"] == [{"joint": "left_hip"}]


def test_source_and_character_in_one_file(walk, tmp_path):
    m = walk.slice_frames(0, 20)
    pos, rot = m.forward_kinematics()
    char = track_from_world_poses(m.skeleton.names, m.skeleton.parents, pos + [1.0, 0, 0], rot)
    out = tmp_path / "both.mcap"
    write_transforms_mcap(out, [track_from_motion(m), char], m.fps)
    assert [s["role"] for s in list_skeletons(out)] == ["source", "character"]
    src = read_mcap(out)
    _assert_same_motion(m, src, tol=0)
    c = read_mcap(out, skeleton="/character")
    np.testing.assert_allclose(c.world_positions(), pos + [1.0, 0, 0], atol=1e-9)
    with pytest.raises(OptionError, match="no skeleton"):
        read_mcap(out, skeleton="/nobody")


# --- foreign layouts -----------------------------------------------------------------
def _write_raw(path: Path, schema_name: str, schema: dict | None, messages, encoding="json", channel_meta=None):
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(schema_name, "jsonschema", json.dumps(schema or {}).encode()) if schema_name else 0
        cid = w.register_channel("/body", encoding, sid, channel_meta or {})
        for k, (t, obj) in enumerate(messages):
            data = obj if isinstance(obj, bytes) else json.dumps(obj).encode()
            w.add_message(cid, log_time=t, data=data, publish_time=t, sequence=k)
        w.finish()


def _stamp(t):
    return {"sec": t // 10**9, "nsec": t % 10**9}


def test_reads_foreign_poses_in_frame(tmp_path, walk):
    """A tracker recording: 15 poses per frame in NITE order, one frame missing."""
    from physmocap.sources.positions import TRACKER_LAYOUTS

    pytest.importorskip("physmocap.sources.profiles", reason="name-mapping profiles not built yet")
    names = TRACKER_LAYOUTS["nite"]
    rng = np.random.default_rng(2)
    base = rng.normal(scale=0.3, size=(15, 3)) + [0, 0, 1.0]
    msgs = []
    dt = 10**9 // 30
    for i in range(30):
        if i == 7:
            continue  # lost frame
        t = 5 * 10**9 + i * dt
        poses = [{"position": dict(zip("xyz", (base[j] + [0.01 * i, 0, 0]).tolist())),
                  "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}} for j in range(15)]  # fmt: skip
        msgs.append((t, {"timestamp": _stamp(t), "frame_id": "world", "poses": poses}))
    out = tmp_path / "nite.mcap"
    _write_raw(out, "foxglove.PosesInFrame", POSES_IN_FRAME_SCHEMA, msgs)
    m = read_mcap(out)
    assert not m.is_rotational and m.num_frames == 30
    assert m.fps == pytest.approx(30.0, rel=1e-6)
    assert set(names) <= set(m.skeleton.names)
    assert np.all(np.isfinite(m.positions))
    head = m.skeleton.index("head")
    np.testing.assert_allclose(m.positions[7, head], base[0] + [0.07, 0, 0], atol=1e-9)  # interpolated
    assert any(g["joint"] == "*" and g["start"] == 7 for g in m.meta["gaps"])


def test_reads_foreign_transform_tree(tmp_path):
    msgs = []
    for i in range(5):
        t = i * 10**8
        q = Rotation.from_euler("z", 0.1 * i).as_quat()
        msgs.append((t, {"transforms": [
            {"timestamp": _stamp(t), "parent_frame_id": "map", "child_frame_id": "hips",
             "translation": {"x": 0.1 * i, "y": 0, "z": 1}, "rotation": dict(zip("xyzw", q.tolist()))},
            {"timestamp": _stamp(t), "parent_frame_id": "hips", "child_frame_id": "knee",
             "translation": {"x": 0, "y": 0, "z": -0.5}, "rotation": {"x": 0, "y": 0, "z": 0, "w": 1}},
        ]}))  # fmt: skip
    out = tmp_path / "tf.mcap"
    _write_raw(out, "foxglove.FrameTransforms", FRAME_TRANSFORMS_SCHEMA, msgs)
    m = read_mcap(out)
    assert m.is_rotational and m.skeleton.names == ("hips", "knee")
    assert m.fps == pytest.approx(10.0)
    np.testing.assert_allclose(m.world_positions()[4], [[0.4, 0, 1], [0.4, 0, 0.5]], atol=1e-12)
    assert m.meta["mcap"]["world_frames"] == ["map"]


# --- errors: one clear InputError each ------------------------------------------------
def test_not_an_mcap_file(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_text("HIERARCHY\nROOT Hips\n")
    with pytest.raises(InputError, match="not an MCAP file"):
        read_mcap(bad)


def test_truncated_file(walk, tmp_path):
    good = tmp_path / "good.mcap"
    write_motion_mcap(walk.slice_frames(0, 30), good)
    data = good.read_bytes()
    for cut in (len(data) // 2, len(data) - 3, 20):
        bad = tmp_path / "cut.mcap"
        bad.write_bytes(data[:cut])
        with pytest.raises(InputError, match="truncated") as e:
            read_mcap(bad)
        assert str(bad) in str(e.value)


def test_corrupt_file(walk, tmp_path):
    good = tmp_path / "good.mcap"
    write_motion_mcap(walk.slice_frames(0, 30), good, compression="none")
    data = bytearray(good.read_bytes())
    for at in (len(data) // 3, len(data) // 2):
        bad_bytes = bytearray(data)
        bad_bytes[at : at + 16] = b"\xff" * 16
        bad = tmp_path / "bad.mcap"
        bad.write_bytes(bytes(bad_bytes))
        with pytest.raises(InputError, match="corrupt MCAP"):
            read_mcap(bad)
    # compressed chunk damaged
    write_motion_mcap(walk.slice_frames(0, 30), good)
    data = bytearray(good.read_bytes())
    data[400:420] = b"\x00" * 20
    bad.write_bytes(bytes(data))
    with pytest.raises(InputError, match="corrupt MCAP"):
        read_mcap(bad)


def test_unknown_schema(tmp_path):
    out = tmp_path / "imu.mcap"
    _write_raw(out, "sensor_msgs.Imu", {"type": "object"}, [(0, {"a": 1})])
    with pytest.raises(InputError, match=r"no skeleton data.*/body \(sensor_msgs.Imu, json\)"):
        read_mcap(out)


def test_protobuf_encoding_is_refused_clearly(tmp_path):
    out = tmp_path / "pb.mcap"
    _write_raw(out, "foxglove.FrameTransforms", None, [(0, b"\x0a\x00")], encoding="protobuf")
    with pytest.raises(InputError, match="protobuf.*JSON-encoded"):
        read_mcap(out)


def test_malformed_messages(tmp_path):
    out = tmp_path / "m.mcap"
    _write_raw(out, "foxglove.FrameTransforms", FRAME_TRANSFORMS_SCHEMA, [(0, b"{not json")])
    with pytest.raises(InputError, match="message 0 on /body: invalid JSON"):
        read_mcap(out)
    bad_num = {"transforms": [{"parent_frame_id": "w", "child_frame_id": "a",
                               "translation": {"x": "1", "y": 0, "z": 0}}]}  # fmt: skip
    _write_raw(out, "foxglove.FrameTransforms", FRAME_TRANSFORMS_SCHEMA, [(0, bad_num)])
    with pytest.raises(InputError, match="'x' must be a finite number"):
        read_mcap(out)
    _write_raw(out, "foxglove.FrameTransforms", FRAME_TRANSFORMS_SCHEMA,
               [(0, b'{"transforms": [{"parent_frame_id": "w", "child_frame_id": "a", '
                    b'"translation": {"x": NaN, "y": 0, "z": 0}}]}')])  # fmt: skip
    with pytest.raises(InputError, match="message 0"):
        read_mcap(out)


def test_writer_refuses_non_finite(walk, tmp_path):
    m = walk.slice_frames(0, 5)
    rot = m.rotations.copy()
    rot[3, 2, 0] = np.nan
    out = tmp_path / "nan.mcap"
    with pytest.raises(OutputError, match="non-finite rotation.*frame 3"):
        write_motion_mcap(m.replace(rotations=rot), out)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_writer_options(walk, tmp_path):
    with pytest.raises(OptionError, match="metres, Z-up"):
        write_motion_mcap(walk.slice_frames(0, 3), tmp_path / "x.mcap", units="cm")
    with pytest.raises(OptionError, match="do not apply"):
        write_motion_mcap(walk.slice_frames(0, 3), tmp_path / "x.mcap", precision=3)


def test_cli_convert_round_trip_and_clean_errors(tmp_path):
    src = shared_file("cmu_12_01_walk.bvh")
    out = tmp_path / "walk.mcap"
    run = [sys.executable, "-m", "physmocap", "convert"]
    r = subprocess.run(run + [str(src), str(out), "--end", "60"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    m = read_mcap(out)
    ref = load_motion(src).slice_frames(0, 60)
    assert np.abs(m.world_positions() - ref.world_positions()).max() <= 1e-6
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(out.read_bytes()[:1000])
    r = subprocess.run(run + [str(bad), str(tmp_path / "o.bvh")], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "truncated MCAP file" in r.stderr and "Traceback" not in r.stderr


def test_character_trajectory_with_source(tmp_path):
    """The retargeted character's bodies as FrameTransforms, beside its source."""
    from physmocap.models import load_character
    from physmocap.trajectory import Trajectory
    from physmocap.export.mcap import write_trajectory_mcap

    character = load_character()
    model = character.model
    qpos = np.tile(model.qpos0, (4, 1))
    qpos[:, 0] = np.linspace(0, 0.3, 4)  # slide the root along x
    traj = Trajectory(character=character, qpos=qpos, fps=30.0)
    sk = Skeleton(names=("a", "b"), parents=[-1, 0], offsets=[[0, 0, 1], [0, 0, 0.5]])
    src = Motion(sk, 30.0, positions=np.tile([[0.0, 0, 1], [0, 0, 1.5]], (4, 1, 1)))
    out = tmp_path / "char.mcap"
    write_trajectory_mcap(traj, out, source=src)
    assert [(s["topic_prefix"], s["role"]) for s in list_skeletons(out)] == [
        ("/source", "source"),
        ("/character", "character"),
    ]
    c = read_mcap(out, skeleton="character")
    pos, _ = traj.body_poses()
    np.testing.assert_allclose(c.world_positions(), pos[:, 1:], atol=1e-9)
    np.testing.assert_array_equal(read_mcap(out).positions, src.positions)


def test_own_recordings_refuse_unit_overrides(walk, tmp_path):
    out = tmp_path / "w.mcap"
    write_motion_mcap(walk.slice_frames(0, 3), out)
    with pytest.raises(OptionError, match="says its own units"):
        read_mcap(out, units="cm")
    assert read_mcap(out, units="m").num_frames == 3
