"""Issue 9, item 3: knees and hands on the floor are detected and honoured like feet."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from kneeling import all_fours_motion
from physmocap.errors import OptionError
from physmocap.ik.body_contacts import BodyContactOptions
from physmocap.ik.contacts import detect_contacts
from physmocap.ik.retarget import map_motion, retarget
from physmocap.metrics.fidelity import actor_joint_positions, character_joint_positions, segment_direction_errors
from physmocap.models.geometry import character_geoms, geom_z_extent
from physmocap.resources import resolve_input
from physmocap.sources import load_motion
from conftest import RETARGET_DIAGNOSTICS

pytestmark = RETARGET_DIAGNOSTICS


@pytest.fixture(scope="module")
def crawl():
    return all_fours_motion()


def _hold(motion) -> slice:
    return slice(int(0.8 * motion.num_frames), motion.num_frames)


def test_knees_and_hands_detected_only_on_the_floor(crawl):
    contacts = detect_contacts(crawl, map_motion(crawl))
    F = crawl.num_frames
    for part in ("left_knee", "right_knee", "left_hand", "right_hand"):
        lab = contacts.body_labels[part]
        assert lab[_hold(crawl)].all(), part  # the held pose
        assert not lab[: int(0.3 * F)].any(), part  # standing
    assert not contacts.body_labels["pelvis"].any()


def test_no_body_contacts_on_a_walk():
    walk = load_motion(resolve_input("example"))
    contacts = detect_contacts(walk, map_motion(walk))
    assert not any(v.any() for v in contacts.body_labels.values())


def test_body_contact_options_are_validated():
    with pytest.raises(OptionError, match="knee_enter"):
        BodyContactOptions(knee_enter=0.3, knee_exit=0.2)
    with pytest.raises(OptionError, match="hand_exit"):
        BodyContactOptions(hand_exit=float("nan"))


def _lowest(traj, frames, words: tuple[str, ...]) -> float:
    """Mean over ``frames`` of the lowest collision geom of bodies whose name contains any of ``words``."""
    model = traj.character.model
    data = mujoco.MjData(model)
    geoms = [g for g in character_geoms(model, collision_only=True) if any(w in model.body(model.geom_bodyid[g]).name for w in words)]
    assert geoms, words
    lows = []
    for t in frames:
        data.qpos[:] = traj.qpos[t]
        mujoco.mj_kinematics(model, data)
        lows.append(min(geom_z_extent(model, data, g)[0] for g in geoms))
    return float(np.mean(lows))


@pytest.mark.parametrize(
    "character,knee,hand",
    [(None, ("shank",), ("hand",)), ("robot", ("shin",), ("lower_arm",))],
    ids=["humanoid", "robot"],
)
def test_all_fours_rests_knees_and_hands_on_the_floor(crawl, character, knee, hand):
    """Before: the legs squatted over feet held sole-down (thighs and shanks more than 45
    degrees off the actor's on half of the clip) and the robot's shins hovered 5.5 cm up."""
    traj = retarget(crawl, character, progress=False)
    hold = range(*_hold(crawl).indices(crawl.num_frames))
    for side in ("left", "right"):
        assert _lowest(traj, hold, tuple(f"{p}{w}" for w in knee for p in (f"{side}_", side[0] + "_"))) < 0.02
        assert _lowest(traj, hold, tuple(f"{p}{w}" for w in hand for p in (f"{side}_", side[0] + "_"))) < 0.01
    errors = segment_direction_errors(
        actor_joint_positions(traj.source_motion, traj.joint_indices), character_joint_positions(traj)
    )
    for seg in ("left_thigh", "right_thigh", "left_shank", "right_shank"):
        assert np.nanpercentile(errors[seg], 95) < 45.0, seg
    assert np.isfinite(traj.qpos).all()


def test_streaming_holds_knees_and_hands_on_the_floor(crawl):
    """The causal variant: the stream detects the crawl's knees and hands and lays them down."""
    from physmocap.ik.stream import stream_motion
    from physmocap.models import load_character

    ch = load_character()
    traj = stream_motion(crawl, ch)
    hold = range(*_hold(crawl).indices(crawl.num_frames))
    for side in ("left", "right"):
        assert _lowest(traj, hold, (f"{side}_shank",)) < 0.03
        assert _lowest(traj, hold, (f"{side}_hand",)) < 0.015
    assert np.isfinite(traj.qpos).all()
    # walking streams are unchanged: no body part comes near the floor
    import physmocap

    walk = physmocap.load_motion("example").slice_frames(1, 121)
    from physmocap.ik.stream import StreamingRetargeter

    live = StreamingRetargeter(ch, skeleton=walk.skeleton, fps=walk.fps, translated=walk.translated)
    for t in range(walk.num_frames):
        live.step(rotations=walk.rotations[t], translations=walk.translations[t])
    assert live.body_contacts is not None and set(live.body_contacts.parts) >= {"left_knee", "right_hand"}
    assert not any(a.anchor is not None for a in live.body_anchors.values())
