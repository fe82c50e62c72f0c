"""Foot contact detection: hand-labelled walk, the other shared clips, options, CSV labels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physmocap.errors import InputError, MappingError, OptionError, PhysmocapWarning
from physmocap.ik.contacts import (
    CONTACT_LABELS,
    ContactDetector,
    ContactOptions,
    ContactStream,
    Contacts,
    contact_points,
    contact_sites_labels,
    detect_contacts,
    detect_point_contacts,
    label_f1,
    load_contact_csv,
    write_contact_csv,
)
from physmocap.sources import load_motion
from physmocap.sources.profiles import map_skeleton

from conftest import shared_file

FIXTURES = Path(__file__).parent / "fixtures" / "contacts"
WALK_LABELS = FIXTURES / "cmu_12_01_walk_stance.csv"

_CACHE: dict[str, tuple] = {}


def clip(name: str):
    """(motion, canonical joint indices) of a shared recording, read once per session."""
    if name not in _CACHE:
        motion = load_motion(shared_file(name))
        _CACHE[name] = (motion, dict(map_skeleton(motion.skeleton).indices))
    return _CACHE[name]


def detected(name: str) -> Contacts:
    key = "contacts:" + name
    if key not in _CACHE:
        _CACHE[key] = detect_contacts(*clip(name))
    return _CACHE[key]


# ---------------------------------------------------------------------------
# Acceptance: the hand-labelled CMU walk
# ---------------------------------------------------------------------------


def test_fixture_is_hand_labelled_and_complete():
    text = WALK_LABELS.read_text()
    assert text.startswith("#") and "by eye" in text
    labels = load_contact_csv(WALK_LABELS, 524)
    for name in CONTACT_LABELS:
        assert 3 <= len(labels.segments(name)) <= 4


@pytest.mark.parametrize("label", CONTACT_LABELS)
def test_walk_agrees_with_hand_labels(label):
    contacts = detected("cmu_12_01_walk.bvh")
    truth = load_contact_csv(WALK_LABELS, contacts.num_frames)
    f1 = label_f1(contacts.labels[label], truth.labels[label])
    assert f1 >= 0.95, f"{label}: F1 {f1:.3f}"


def test_walk_at_30_hz_agrees_with_hand_labels():
    motion, idx = clip("cmu_12_01_walk.bvh")
    truth = load_contact_csv(WALK_LABELS, motion.num_frames)
    slow = motion.resample(30.0)
    contacts = detect_contacts(slow, idx)
    # compare on the 120 Hz frames: each takes the label of the nearest 30 Hz frame
    nearest = np.clip(np.round(np.arange(motion.num_frames) / motion.fps * slow.fps).astype(int), 0, slow.num_frames - 1)
    for label in CONTACT_LABELS:
        f1 = label_f1(contacts.labels[label][nearest], truth.labels[label])
        assert f1 >= 0.93, f"{label} at 30 Hz: F1 {f1:.3f}"


@pytest.mark.parametrize("name", ["pymo_walk.bvh", "cmu_01_01_jumps.bvh", "optitrack_hops_crouch.bvh"])
def test_30_hz_agrees_with_120_hz(name):
    motion, idx = clip(name)
    fast = detected(name)
    slow = detect_contacts(motion.resample(30.0), idx)
    nearest = np.clip(np.round(np.arange(motion.num_frames) / motion.fps * 30.0).astype(int), 0, slow.num_frames - 1)
    for label in CONTACT_LABELS:
        assert label_f1(slow.labels[label][nearest], fast.labels[label]) >= 0.93, label


def test_walk_floor_is_a_slightly_tilted_plane():
    contacts = detected("cmu_12_01_walk.bvh")
    floor = contacts.floor
    # the capture volume of this take is tilted along the walking direction (-Y)
    slope = np.hypot(*floor.slope)
    assert 0.004 < slope < 0.015
    assert abs(floor.slope[1]) > 10 * abs(floor.slope[0])
    # the toe end is the lowest point; the ankle joint stands a few cm higher
    assert min(floor.levels.values()) == 0.0
    assert 0.03 < floor.levels["left_heel"] < 0.07


# ---------------------------------------------------------------------------
# The other shared clips
# ---------------------------------------------------------------------------


def test_jumps_have_no_contact_in_flight():
    contacts = detected("cmu_01_01_jumps.bvh")
    h = contacts.heights
    airborne = np.ones(contacts.num_frames, dtype=bool)
    for side in ("left", "right"):
        airborne &= np.minimum(h[f"{side}_ball"], h[f"{side}_toe_end"]) > 0.10
        airborne &= h[f"{side}_heel"] > 0.15
    assert airborne.sum() > 100
    for label in CONTACT_LABELS:
        assert not contacts.labels[label][airborne].any(), label
    # about a dozen forward jumps: flight phases separate the stance phases
    any_contact = np.zeros(contacts.num_frames, dtype=bool)
    for label in CONTACT_LABELS:
        any_contact |= contacts.labels[label]
    flights = [s for s in _runs(~any_contact) if s[1] - s[0] >= 0.05 * contacts.fps]
    assert 9 <= len(flights) <= 16


def test_optitrack_two_hops_then_standing():
    contacts = detected("optitrack_hops_crouch.bvh")
    any_contact = np.zeros(contacts.num_frames, dtype=bool)
    for label in CONTACT_LABELS:
        any_contact |= contacts.labels[label]
    flights = _runs(~any_contact)
    assert len(flights) == 2, flights
    for a, b in flights:
        assert a < 300 and 10 <= b - a <= 60
    # squats, bend and crouch: the feet stay down
    rest = slice(300, None)
    for label in ("left_toe", "right_toe"):
        assert contacts.labels[label][rest].mean() > 0.99
    # the single lowest toe sample is below the floor estimate (an outlier, not the floor)
    lowest = min(contacts.heights[p].min() for p in ("left_toe_end", "right_toe_end"))
    assert lowest < -0.01
    assert abs(contacts.floor.height) < 0.01


def test_pymo_walk_alternates_feet():
    contacts = detected("pymo_walk.bvh")
    for side in ("left", "right"):
        toe = contacts.labels[f"{side}_toe"]
        assert 8 <= len(_runs(toe)) <= 11
        assert 0.35 < toe.mean() < 0.65
    # both feet are never off the floor together for long in a walk
    any_contact = np.zeros(contacts.num_frames, dtype=bool)
    for label in CONTACT_LABELS:
        any_contact |= contacts.labels[label]
    assert max((b - a for a, b in _runs(~any_contact)), default=0) < 0.1 * contacts.fps


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, bool), [False]]).astype(np.int8)
    d = np.flatnonzero(np.diff(m))
    return list(zip(d[::2].tolist(), d[1::2].tolist()))


# ---------------------------------------------------------------------------
# The state machine
# ---------------------------------------------------------------------------


def _run_detector(h, v, fps, **opts):
    det = ContactDetector(["toe"], fps, ContactOptions(**opts))
    out = [det.step([a], [b])[0] for a, b in zip(h, v)]
    det.finish()
    return np.array(out), det


def test_hysteresis_does_not_flicker():
    fps = 120.0
    t = np.arange(240)
    # resting at 1.8 cm +- 0.6 cm noise: between the enter (1.5) and exit (4) heights
    h = 0.018 + 0.006 * np.sin(t * 1.7)
    h[:12] = 0.0  # starts down
    out, det = _run_detector(h, np.zeros_like(h), fps)
    assert out[12:].all()  # once in contact, noise below the exit height keeps it
    assert len(det.transitions) == 1


def test_run_over_blocks_is_step_by_step(monkeypatch):
    """run() turns the clip into Python numbers a block of frames at a time: the state
    carries over the blocks' seams, so it commits what stepping frame by frame commits."""
    import physmocap.ik.contacts as contacts

    fps, F = 120.0, 400
    t = np.arange(F)
    h = np.stack([0.05 * (np.sin(t * 0.11) > 0), 0.05 * (np.sin(t * 0.07 + 1.0) > 0)], axis=1)
    v = np.abs(np.stack([np.cos(t * 0.05), np.sin(t * 0.03)], axis=1)) * 0.2
    c = np.zeros_like(h)
    c[::37] = np.nan  # unknown samples hold the count, across a seam too
    stepped = ContactDetector(["heel", "toe"], fps)
    for frame in range(F):
        stepped.step(h[frame], v[frame], c[frame])
    monkeypatch.setattr(contacts, "RUN_BLOCK_FRAMES", 7)
    run = ContactDetector(["heel", "toe"], fps)
    run.run(h, v, c)
    assert len(stepped.transitions) > 6
    assert run.transitions == stepped.transitions
    assert (run.state, run.count, run.frame) == (stepped.state, stepped.count, stepped.frame)


def test_min_durations_are_seconds_not_frames():
    for fps in (30.0, 120.0):
        n = int(fps)
        h = np.full(n, 0.10)
        h[n // 4 : n // 4 + max(1, int(0.02 * fps))] = 0.0  # a 20 ms touch: ignored
        h[n // 2 :] = 0.0  # a real landing
        out, _ = _run_detector(h, np.zeros(n), fps)
        assert not out[: n // 2].any()
        assert out[-1]


def test_missing_samples_hold_the_state():
    h = np.zeros(60)
    h[30:40] = np.nan
    out, _ = _run_detector(h, np.zeros(60), 120.0)
    assert out[10:].all()


def test_options_are_validated():
    with pytest.raises(OptionError, match="heel_height_enter"):
        ContactOptions(heel_height_enter=0.05, heel_height_exit=0.02)
    with pytest.raises(OptionError, match="min_contact"):
        ContactOptions(min_contact=-1)
    with pytest.raises(OptionError, match="speed_enter"):
        ContactOptions(speed_enter=2.0)
    ContactOptions(toe_lift_speed=float("inf"))  # disables that exit test


# ---------------------------------------------------------------------------
# Invariance (synthetic gait) and streaming
# ---------------------------------------------------------------------------


def _synthetic_gait(fps: float, seconds: float = 4.0) -> dict[str, np.ndarray]:
    """Two feet alternating 0.6 s stance and 0.4 s swing, walking along +x."""
    t = np.arange(int(seconds * fps)) / fps
    pts = {}
    for side, phase in (("left", 0.0), ("right", 0.5)):
        u = ((t / 1.0) + phase) % 1.0
        swing = u >= 0.6
        s = np.where(swing, (u - 0.6) / 0.4, 0.0)
        steps = np.floor(t / 1.0 + phase)
        x = 1.2 * (steps + np.where(swing, 0.5 - 0.5 * np.cos(np.pi * s), 0.0))
        lift = np.where(swing, 0.12 * np.sin(np.pi * s), 0.0)
        y = 0.1 if side == "left" else -0.1
        pts[f"{side}_heel"] = np.column_stack([x, np.full_like(x, y), 0.08 + lift])
        pts[f"{side}_ball"] = np.column_stack([x + 0.15, np.full_like(x, y), 0.03 + lift])
        pts[f"{side}_toe_end"] = np.column_stack([x + 0.2, np.full_like(x, y), 0.01 + lift])
    return pts


@settings(max_examples=15, deadline=None)
@given(
    yaw=st.floats(-np.pi, np.pi),
    shift=st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-2, 2)),
)
def test_labels_do_not_depend_on_where_the_clip_is(yaw, shift):
    pts = _synthetic_gait(60.0)
    base = detect_point_contacts(pts, 60.0)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    moved = {k: v @ R.T + np.array(shift) for k, v in pts.items()}
    other = detect_point_contacts(moved, 60.0)
    for label in CONTACT_LABELS:
        np.testing.assert_array_equal(base.labels[label], other.labels[label])
    assert other.floor.height == pytest.approx(base.floor.height + shift[2], abs=1e-6)


def test_synthetic_gait_stance_is_found_at_any_rate():
    for fps in (30.0, 60.0, 120.0):
        pts = _synthetic_gait(fps)
        t = np.arange(len(pts["left_heel"])) / fps
        truth = ((t % 1.0) < 0.6)
        contacts = detect_point_contacts(pts, fps)
        assert label_f1(contacts.labels["left_toe"], truth) > 0.95
        assert label_f1(contacts.labels["left_heel"], truth) > 0.9


def test_stream_is_causal_and_close_to_batch():
    motion, idx = clip("cmu_12_01_walk.bvh")
    batch = detected("cmu_12_01_walk.bvh")
    pts = contact_points(idx)
    world = motion.world_positions()[:, list(pts.values())]

    def run(positions):
        stream = ContactStream(list(pts), motion.fps, batch.floor)
        return {k: np.array(v) for k, v in _collect(stream, positions).items()}

    a = run(world)
    changed = world.copy()
    changed[300:] += np.array([0.3, -0.2, 0.25])  # alter the future from frame 300 on
    b = run(changed)
    for label in CONTACT_LABELS:
        np.testing.assert_array_equal(a[label][:300], b[label][:300])
        assert label_f1(a[label], batch.labels[label]) > 0.8


def _collect(stream, positions):
    out = {k: [] for k in CONTACT_LABELS}
    for x in positions:
        for k, v in stream.step(x).items():
            out[k].append(v)
    return out


def test_missing_ankle_is_a_mapping_error():
    with pytest.raises(MappingError, match="right ankle"):
        contact_points({"left_ankle": 3, "left_toe": 4})


def test_toe_falls_back_to_the_heel_without_toe_joints():
    pts = _synthetic_gait(60.0)
    heels = {k: v for k, v in pts.items() if k.endswith("heel")}
    contacts = detect_point_contacts(heels, 60.0)
    np.testing.assert_array_equal(contacts.labels["left_toe"], contacts.labels["left_heel"])


# ---------------------------------------------------------------------------
# User labels (CSV)
# ---------------------------------------------------------------------------


def test_csv_round_trip(tmp_path):
    contacts = detected("cmu_12_01_walk.bvh")
    out = write_contact_csv(contacts, tmp_path / "c.csv", comment="detected\nby physmocap")
    back = load_contact_csv(out, contacts.num_frames)
    for label in CONTACT_LABELS:
        np.testing.assert_array_equal(back.labels[label], contacts.labels[label])
    assert out.read_text().startswith("# detected\n# by physmocap\npoint,start,end\n")


def test_csv_inclusive_ranges_and_whole_foot(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("point,first,last\nleft,0,9\nright_heel,5,5\n\nright_toe,3,4\n")
    c = load_contact_csv(p, 20)
    assert c.labels["left_heel"][:10].all() and not c.labels["left_heel"][10:].any()
    assert c.labels["left_toe"].sum() == 10
    assert c.labels["right_heel"].sum() == 1 and c.labels["right_heel"][5]
    assert c.segments("right_toe") == [(3, 5)]


@pytest.mark.parametrize(
    "text, line, message",
    [
        ("point,begin,end\nleft_heel,0,3\n", 1, "header"),
        ("# c\npoint,start,end\nleft_hell,0,3\n", 3, "unknown contact point 'left_hell'"),
        ("point,start,end\nleft_heel,0,x\n", 2, "integers"),
        ("point,start,end\nleft_heel,5,5\n", 2, "empty or outside"),
        ("point,start,end\nleft_heel,0,21\n", 2, "outside the clip's frames 0 to 19"),
        ("point,start,end\nleft_heel,0\n", 2, "3 columns"),
    ],
)
def test_csv_errors_name_file_and_line(tmp_path, text, line, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError) as err:
        load_contact_csv(p, 20)
    assert f"bad.csv:{line}:" in str(err.value)
    assert message in str(err.value)


def test_csv_missing_file_and_unlabelled_points(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_contact_csv(tmp_path / "nope.csv", 10)
    p = tmp_path / "c.csv"
    p.write_text("point,start,end\nleft_heel,0,3\n")
    with pytest.warns(PhysmocapWarning, match="right_toe"):
        c = load_contact_csv(p, 10)
    assert not c.labels["right_toe"].any()


# ---------------------------------------------------------------------------
# Characters
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["humanoid", "robot"])
def test_labels_map_onto_character_sites(name):
    from physmocap.models import load_character

    character = load_character(name)
    contacts = detected("cmu_12_01_walk.bvh")
    sites = contact_sites_labels(contacts, character)
    for side, names in character.contacts.items():
        np.testing.assert_array_equal(sites[names[0]], contacts.labels[f"{side}_heel"])
        for s in names[1:]:
            np.testing.assert_array_equal(sites[s], contacts.labels[f"{side}_toe"])
    assert set(sites) == {s for names in character.contacts.values() for s in names}
