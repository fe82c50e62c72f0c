"""Feet levelled from the actor's stance, and knees that bend forward."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmocap.ik.footlevel import level_feet
from physmocap.ik.footplan import knee_between

NAMES = ("left_ankle", "left_toe", "left_toe_end")


def _rest(pitch_deg: float = 0.0):
    """A character foot: ankle site 7 cm up, toe joint 13 cm ahead and 2 cm up, tip 7 cm beyond."""
    q0 = Rotation.from_euler("y", pitch_deg, degrees=True)
    return {
        "left_ankle": (np.array([0.0, 0.1, 0.07]), q0.as_quat()),
        "left_toe": (np.array([0.13, 0.1, 0.02]), q0.as_quat()),
        "left_toe_end": (np.array([0.20, 0.1, 0.02]), q0.as_quat()),
    }


@pytest.mark.parametrize("tilt_deg, rest_pitch", [(25.0, 0.0), (-12.0, 0.0), (20.0, 15.0)])
def test_a_flat_actor_foot_becomes_the_characters_flat_foot(tilt_deg, rest_pitch):
    """Targets whose foot orientation is off by a constant tilt (a skeleton that puts its toe
    joint elsewhere) are levelled on the stance frames; heading and swing pitch are kept."""
    F, fps = 120, 60.0
    rest = _rest(rest_pitch)
    heading = np.linspace(0.0, 1.2, F)  # the actor turns while walking
    swing_pitch = np.where(np.arange(F) < 80, 0.0, np.linspace(0.0, 0.6, F))  # heel rises after frame 80
    tilt = Rotation.from_euler("y", tilt_deg, degrees=True)
    actor = Rotation.from_euler("zy", np.stack([heading, swing_pitch], axis=1))
    q = (actor * tilt * Rotation.from_quat(rest["left_ankle"][1])).as_quat()
    ori = np.zeros((F, 3, 4))
    ori[..., 3] = 1.0
    ori[:, 0] = q
    pos = np.zeros((F, 3, 3))
    pos[:, 0] = [0.0, 0.1, 0.09]
    turn = Rotation.from_euler("z", heading[:, None])
    pos[:, 1] = pos[:, 0] + turn.apply([0.12, 0.0, 0.03])  # the actor's toe sits higher than the character's
    pos[:, 2] = pos[:, 1] + turn.apply([0.06, 0.0, 0.0])
    down = np.arange(F) < 80
    labels = {"left_heel": down, "left_toe": down}
    has_q = np.array([True, False, False])
    before_pos, before_ori = pos.copy(), ori.copy()
    new_pos, new_ori, levels = level_feet(pos, ori, has_q, NAMES, labels, rest, fps)
    assert np.array_equal(pos, before_pos) and np.array_equal(ori, before_ori)  # inputs untouched
    assert len(levels) == 1 and levels[0].side == "left" and levels[0].correction_deg == pytest.approx(abs(tilt_deg), abs=0.5)
    rel = Rotation.from_quat(new_ori[:, 0]) * Rotation.from_quat(rest["left_ankle"][1]).inv()
    want = Rotation.from_euler("zy", np.stack([heading, swing_pitch], axis=1))
    assert np.degrees((rel * want.inv()).magnitude()).max() < 0.5
    # the toe joint sits where the character's foot puts it (flat: 5 cm below the ankle site)
    assert np.allclose(new_pos[down, 1, 2] - new_pos[down, 0, 2], -0.05, atol=1e-6)
    assert np.allclose(np.linalg.norm(new_pos[:, 1] - new_pos[:, 0], axis=1), np.hypot(0.13, 0.05))
    # the toe tip keeps its length from the toe joint
    assert np.allclose(np.linalg.norm(new_pos[:, 2] - new_pos[:, 1], axis=1), 0.06)


def test_a_foot_never_flat_is_left_alone():
    F = 50
    rest = _rest()
    ori = np.zeros((F, 3, 4))
    ori[..., 3] = 1.0
    ori[:, 0] = Rotation.from_euler("y", 30, degrees=True).as_quat()
    pos = np.zeros((F, 3, 3))
    labels = {"left_heel": np.zeros(F, bool), "left_toe": np.ones(F, bool)}  # on tiptoe throughout
    new_pos, new_ori, levels = level_feet(pos, ori, np.array([True, False, False]), NAMES, labels, rest, 30.0)
    assert levels == [] and np.array_equal(new_pos, pos) and np.array_equal(new_ori, ori)


def test_a_straight_actor_leg_bends_forward_not_sideways():
    """The actor's knee lies on the hip-ankle line up to capture noise (1 mm to the side); the
    planned ankle is 5 cm closer, so the character's knee must bend: over the toes."""
    hip = np.array([[0.0, 0.0, 0.9]])
    ankle = np.array([[0.0, 0.0, 0.07]])
    knee0 = np.array([[0.0, -0.001, 0.485]])  # straight, a millimetre of noise to the side
    toe_dir = np.array([[1.0, 0.0, -0.3]])
    knee = knee_between(hip, ankle + [0.0, 0.0, 0.05], knee0, 0.42, 0.42, toe_dir)
    off = knee[0] - np.array([0.0, 0.0, knee[0, 2]])
    assert off[0] > 0.1 and abs(off[1]) < 0.06 * off[0]  # 3 degrees at most
    # a visibly bent actor knee keeps its own plane
    bent = np.array([[0.0, -0.08, 0.485]])
    knee = knee_between(hip, ankle + [0.0, 0.0, 0.05], bent, 0.42, 0.42, toe_dir)
    assert knee[0, 1] < -0.1 and abs(knee[0, 0]) < 0.4 * abs(knee[0, 1])
    # both lengths kept
    assert np.linalg.norm(knee[0] - hip[0]) == pytest.approx(0.42, abs=1e-6)


def test_feet_are_levelled_without_planting_too():
    """Pure tracking (--no-plant) levels the feet like planting does; contacts=False does not."""
    import warnings

    from physmocap.ik.retarget import retarget
    from physmocap.resources import example_clip
    from physmocap.sources import load_motion

    motion = load_motion(example_clip())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        free = retarget(motion, None, progress=False, plant=False, end=200)
        planted = retarget(motion, None, progress=False, end=200)
        bare = retarget(motion, None, progress=False, contacts=False, end=200)
    sides = {lv.side: lv.correction_deg for lv in free.targets.info["foot_levels"]}
    assert set(sides) == {"left", "right"} and min(sides.values()) > 10.0  # CMU's feet: about 24 degrees
    assert [lv.side for lv in planted.targets.info["foot_levels"]] == ["left", "right"]
    assert "foot_levels" not in bare.targets.info


def test_undefined_frames_are_left_as_they_are():
    """A positional source may leave a lost joint's target undefined (NaN) on some frames:
    those frames are skipped, never turned into an error or spread."""
    F = 60
    rest = _rest()
    ori = np.zeros((F, 3, 4))
    ori[..., 3] = 1.0
    ori[:, 0] = Rotation.from_euler("y", 20, degrees=True).as_quat()
    ori[10:13, 0] = np.nan
    pos = np.zeros((F, 3, 3))
    pos[:, 1] = [0.13, 0.0, 0.0]
    pos[:, 2] = [0.2, 0.0, 0.0]
    pos[30, 1] = np.nan
    labels = {"left_heel": np.ones(F, bool), "left_toe": np.ones(F, bool)}
    new_pos, new_ori, levels = level_feet(pos, ori, np.array([True, False, False]), NAMES, labels, rest, 30.0)
    assert len(levels) == 1 and levels[0].stance_frames == F - 4
    assert np.isnan(new_ori[10:13, 0]).all() and np.isnan(new_pos[30, 1]).all()
    ok = np.ones(F, bool)
    ok[[10, 11, 12, 30]] = False
    assert np.isfinite(new_ori[ok]).all() and np.isfinite(new_pos[ok]).all()


def test_toes_are_levelled_with_the_foot():
    """A skeleton whose toe bone points 30 degrees down while the actor stands flat gets the
    character's flat toes on the stance frames; the actor's toe flexion relative to that (toes
    bending after frame 80) is kept."""
    F, fps = 120, 60.0
    rest = _rest()
    ori = np.zeros((F, 3, 4))
    ori[..., 3] = 1.0
    ori[:, 0] = rest["left_ankle"][1]
    pos = np.zeros((F, 3, 3))
    pos[:, 0] = [0.0, 0.1, 0.07]
    pos[:, 1] = [0.13, 0.1, 0.02]
    bend = np.where(np.arange(F) < 80, 0.0, np.radians(20.0))  # the toes curl 20 degrees later
    down = np.radians(30.0) + bend
    pos[:, 2] = pos[:, 1] + 0.07 * np.stack([np.cos(down), np.zeros(F), -np.sin(down)], axis=1)
    stance = np.arange(F) < 80
    labels = {"left_heel": stance, "left_toe": stance}
    new_pos, _, levels = level_feet(pos, ori, np.array([True, False, False]), NAMES, labels, rest, fps)
    seg = new_pos[:, 2] - new_pos[:, 1]
    pitch = np.degrees(np.arctan2(-seg[:, 2], seg[:, 0]))
    assert np.allclose(pitch[stance], 0.0, atol=1e-6)  # flat, as the character's rest toes
    assert np.allclose(pitch[~stance], 20.0, atol=1e-6)  # the actor's curl, relative to flat
    assert np.allclose(np.linalg.norm(seg, axis=1), 0.07)


def test_a_pitched_toe_segment_rests_on_its_lowest_point():
    """ToeContact.lowest: a capsule toe (radius 1 cm from the toe joint to the tip) pitched 60
    degrees down rests on the tip's end cap, not on its flat-toe contact site."""
    from physmocap.ik.footplan import ToeContact

    seg = ToeContact(
        direction=np.array([0.07, 0.0, 0.0]),
        offsets=np.array([[0.0, 0.0, 0.0], [0.07, 0.0, 0.0]]),
        radii=np.array([0.01, 0.01]),
        height=0.0,
    )
    toe = np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.1]])
    a = np.radians([0.0, 60.0])
    tip = toe + 0.07 * np.stack([np.cos(a), np.zeros(2), -np.sin(a)], axis=1)
    low = seg.lowest(toe, tip)
    assert np.allclose(low[:, 2], tip[:, 2] - 0.01)
    assert np.allclose(low[1, :2], tip[1, :2])
