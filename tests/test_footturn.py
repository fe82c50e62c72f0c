"""Turning a planted foot towards its target heading (physmocap.ik.footturn)."""

from __future__ import annotations

import numpy as np
import pytest

from physmocap.ik.footturn import BEND_FULL, LEG_SHARE, HeadingFollower, knee_plane, wrap_angle

FPS = 120.0
FREE = np.radians(2.0)
RATE = 1.0
#: targets: 0 hip, 1 knee, 2 ankle, 3 toe
HIP, KNEE, ANKLE, TOE = range(4)
#: contact sites heel, ball, tip at rest (metres), the foot facing +X
REST_SITES = np.array([[-0.05, 0.0, 0.0], [0.10, 0.01, 0.0], [0.15, 0.0, 0.0]])


def _rot_z(a: float) -> np.ndarray:
    """x-y-z-w quaternion of a turn by ``a`` about Z."""
    return np.array([0.0, 0.0, np.sin(a / 2.0), np.cos(a / 2.0)])


def _follower(orientation: bool = True, legs: bool = False) -> HeadingFollower:
    feet = {"left": (ANKLE, TOE, np.array([0, 1, 2]), REST_SITES, np.array([0.0, 0.0, 0.0, 1.0]),
                     np.array([0.12, 0.0, -0.05]))}
    return HeadingFollower(np.array([False, False, orientation, False]), feet, FPS, FREE, RATE, np.radians(60.0),
                           {"left": (HIP, KNEE, ANKLE)} if legs else None)


def _anchors(heading: float, held=(0, 2)) -> tuple[np.ndarray, np.ndarray]:
    """Anchors of the rest sites turned by ``heading`` about the heel, and the locked mask."""
    c, s = np.cos(heading), np.sin(heading)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    locked = np.zeros(3, dtype=bool)
    locked[list(held)] = True
    return REST_SITES @ R.T, locked


def _targets(heading: float, knee_turn: float | None = None, bend: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Targets (hip, knee, ankle, toe) of a leg whose foot faces ``heading`` and whose knee
    plane faces ``knee_turn`` (default: the foot's), the knee bent by ``bend``."""
    knee_turn = heading if knee_turn is None else knee_turn
    fwd = np.array([np.cos(knee_turn), np.sin(knee_turn), 0.0])
    ankle = np.array([0.0, 0.0, 0.08])
    knee = ankle + 0.4 * (np.cos(bend / 2.0) * np.array([0, 0, 1.0]) + np.sin(bend / 2.0) * fwd)
    hip = knee + 0.4 * (np.cos(bend / 2.0) * np.array([0, 0, 1.0]) - np.sin(bend / 2.0) * fwd)
    toe = ankle + 0.12 * np.array([np.cos(heading), np.sin(heading), 0.0]) + np.array([0, 0, -0.05])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (4, 1))
    q[ANKLE] = _rot_z(heading)
    return np.array([hip, knee, ankle, toe]), q


def _run(follower: HeadingFollower, held_heading: float, targets, legs_now=None, held=(0, 2)) -> float:
    """The held heading after the follower's turns on every target frame (turning the anchors
    about the last held site as FootPlanter.turn does)."""
    anchors, locked = _anchors(held_heading, held)
    for positions, orientations in targets:
        turn = follower.turns(positions, orientations, None, locked, anchors, legs_now)["left"]
        idx = np.flatnonzero(locked)
        pivot = anchors[idx[-1], :2].copy()
        c, s = np.cos(turn), np.sin(turn)
        d = anchors[idx, :2] - pivot
        anchors[idx, 0] = pivot[0] + c * d[:, 0] - s * d[:, 1]
        anchors[idx, 1] = pivot[1] + s * d[:, 0] + c * d[:, 1]
    return follower.held_heading("left", np.flatnonzero(locked), anchors)


@pytest.mark.parametrize("orientation", [True, False])
def test_a_foot_caught_off_its_heading_turns_onto_it_at_the_rate(orientation):
    f = _follower(orientation)
    target = _targets(0.0)
    off = np.radians(10.0)
    one = _run(f, off, [target])
    assert one == pytest.approx(off - RATE / FPS, abs=1e-9)  # the first frame: at most the rate
    f = _follower(orientation)
    end = _run(f, off, [target] * 60)
    assert end == pytest.approx(FREE, abs=1e-9)  # then to the dead band's edge, no further


def test_drift_within_the_dead_band_does_not_turn_the_foot():
    f = _follower()
    held = np.radians(1.5)
    assert _run(f, held, [_targets(0.0), _targets(np.radians(-0.4)), _targets(np.radians(0.3))]) == pytest.approx(held)


def test_a_spin_on_a_planted_foot_is_followed_at_once():
    """A target turning 5 degrees a frame (600 deg/s) is followed within the dead band."""
    f = _follower()
    frames = [_targets(np.radians(5.0 * k)) for k in range(30)]
    end = _run(f, 0.0, frames)
    assert abs(wrap_angle(end - np.radians(5.0 * 29))) <= FREE + 1e-9


def test_every_pair_of_held_points_reads_the_same_heading():
    f = _follower()
    a, _ = _anchors(np.radians(33.0))
    for pair in ((0, 1), (0, 2), (1, 2), (0, 1, 2)):
        assert f.held_heading("left", np.array(pair), a) == pytest.approx(np.radians(33.0))


def test_knee_plane_heading_and_bend():
    positions, _ = _targets(0.0, knee_turn=np.radians(30.0), bend=np.radians(60.0))
    heading, bend = knee_plane(*positions[:3])
    assert heading == pytest.approx(np.radians(30.0))
    assert bend == pytest.approx(np.radians(60.0))
    straight, _ = _targets(0.0)
    assert knee_plane(*straight[:3])[1] == pytest.approx(0.0, abs=1e-9)


def test_a_bent_leg_holds_its_foot_between_the_actors_foot_and_knee():
    """The actor's knee plane 20 degrees off its foot, the character's knee plane on its held
    foot: the foot is held LEG_SHARE of the way towards the heading that lines the knees up;
    a straight leg holds the foot on the actor's foot."""
    knee = np.radians(20.0)
    bent = _targets(0.0, knee_turn=knee, bend=BEND_FULL + 0.2)
    def legs_now(held: float):
        p, _ = _targets(held, bend=BEND_FULL + 0.2)
        return {"left": p[:3]}
    f = _follower(legs=True)
    anchors, locked = _anchors(0.0)
    aim = f.reference("left", 0.0, 0.0, bent[0], None, legs_now(0.0)["left"])
    assert aim == pytest.approx(LEG_SHARE * knee)
    straight = _targets(0.0, knee_turn=knee)
    assert f.reference("left", 0.0, 0.0, straight[0], None, legs_now(0.0)["left"]) == pytest.approx(0.0)


def test_a_knee_bending_the_other_way_gives_no_aim():
    """A character whose knee plane points away from the actor's (a reverse knee) would aim
    the foot 180 degrees round; beyond MAX_KNEE_TURN the foot keeps its target heading."""
    f = _follower(legs=True)
    bend = BEND_FULL + 0.2
    actor, _ = _targets(0.0, bend=bend)
    backwards, _ = _targets(np.pi, bend=bend)  # the character's knee pointing backwards
    assert f.reference("left", 0.0, 0.0, actor, None, backwards[:3]) == pytest.approx(0.0)


def test_without_orientations_the_heading_comes_from_the_toe():
    f = _follower(orientation=True)
    positions, _ = _targets(np.radians(30.0))
    assert f.target_heading("left", positions, None, None) == pytest.approx(
        f.target_heading("left", *_targets(np.radians(30.0)), None))


def test_a_foot_whose_contact_sites_are_stacked_is_not_turned():
    """Heel and toe sites at one spot give two held points no heading: no follower for it."""
    import dataclasses

    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("humanoid")
    stacked = dataclasses.replace(ch, contacts={"left": ("left_heel", "left_heel"), "right": ch.contacts["right"]})
    names = tuple(ch.tracked)
    planting = Planting(stacked, names, FPS, anchored=False, has_orientation=np.ones(len(names), dtype=bool))
    assert set(planting._turner.feet) == {"right"}
