"""Foot planting (issue 5): acceptance on every shared BVH clip onto both characters, plus
the behaviours the metrics cannot see (feasible double support, causal hand-back)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import RETARGET_DIAGNOSTICS, SHARED_BVH, retargeted
from physmocap import metrics

pytestmark = RETARGET_DIAGNOSTICS

#: Known shortfalls of the offline foot plan, (clip, character) -> reason (strict xfail).  The
#: PyMO humanoid (touchdown outliers lifted its mean flat-stance skating to 1.3 cm/s) passes
#: since the feet are levelled from the actor's stance (physmocap.ik.footlevel).
KNOWN: dict[tuple[str, str], str] = {}
CASES = [
    pytest.param(clip, ch, marks=pytest.mark.xfail(reason=KNOWN[(clip, ch)], strict=True))
    if (clip, ch) in KNOWN
    else (clip, ch)
    for clip in SHARED_BVH
    for ch in ("humanoid", "robot")
]


def _flat_stance_skating(traj) -> dict:
    """Skating of the contact sites while their foot stands flat (heel and toe labelled) and
    the site rests on the floor (within RESTING_HEIGHT, 2 mm, on the frame and both of its
    neighbours: the speed is a central difference), the fidelity figures' definition of a
    geom resting on the floor.  While only the toes are down the foot rolls over its toes (or
    its front edge) and the sites under the heel's body move with the roll; a toe tip still
    coming down onto the floor arcs forward as its toes flatten: neither is a slide (a 1 cm
    band counted the arc, and so favoured toes left bent 1-2 cm up for the whole stance)."""
    from physmocap.metrics.fidelity import RESTING_HEIGHT

    labels = traj.contacts.labels
    cols, masks = [], []
    for side in sorted(traj.character.contacts):
        flat = labels[f"{side}_heel"] & labels[f"{side}_toe"]
        for site in traj.character.contacts[side]:
            cols.append(site)
            masks.append(flat)
    pos = traj.site_positions(cols)
    down = metrics.character_stance(pos[..., 2], 0.0, tol=RESTING_HEIGHT)
    resting = down.copy()
    resting[1:] &= down[:-1]
    resting[:-1] &= down[1:]
    return metrics.skating(pos, traj.fps, resting & np.stack(masks, axis=1))


def _flat_stance_foot_slip(traj) -> np.ndarray:
    """cm/s per flat-foot transition: the slip of a foot's resting contact sites taken as a
    whole (:func:`~physmocap.metrics.fidelity.pivot_slip`): a foot turning about a site it
    stands on pivots with the actor and does not slip."""
    from physmocap.metrics.fidelity import RESTING_HEIGHT, pivot_slip

    labels = traj.contacts.labels
    out = []
    for side in sorted(traj.character.contacts):
        sites = list(traj.character.contacts[side])
        pos = traj.site_positions(sites)
        flat = labels[f"{side}_heel"] & labels[f"{side}_toe"]
        down = pos[..., 2] <= RESTING_HEIGHT
        for t in np.flatnonzero(flat[:-1] & flat[1:]):
            rest = down[t] & down[t + 1]
            if rest.any():
                out.append(pivot_slip(pos[t, rest, :2], pos[t + 1, rest, :2]) * traj.fps * 100.0)
    return np.asarray(out)


@pytest.mark.parametrize("clip,character", CASES)
def test_planted_feet_do_not_skate_sink_or_hover(clip, character):
    _, traj = retargeted(clip, character)
    contacts = traj.contacts
    assert contacts is not None and any(lab.any() for lab in contacts.labels.values())
    slip = _flat_stance_foot_slip(traj)
    assert slip.size > 0
    assert slip.mean() < 1.0 and np.percentile(slip, 95) < 3.0, (slip.mean(), np.percentile(slip, 95))
    # every site on its own, pivots about another site included: the PyMO actor's flat feet
    # turn by up to 9 degrees over a stance and the heel sites swivel with them beyond
    # PlantOptions.pivot_threshold (2.1 cm/s humanoid, 2.8 robot; the actor's toe joints 40 in
    # their stance band)
    skating = _flat_stance_skating(traj)
    assert skating["stance_samples"] > 0
    assert skating["mean_cm_s"] < 4.0, skating
    pen = metrics.penetration(traj.model, traj.qpos)
    assert pen["max_mm"] < 2.0, pen
    hover = metrics.character_hovering(traj, contacts)
    assert hover["median_mm"] < 5.0, hover


def test_source_clips_do_slide(shared_bvh):
    """The raw captures slide (so the figures above are the planting's doing)."""
    from physmocap.ik.retarget import map_motion
    from physmocap.sources import load_motion

    motion = load_motion(shared_bvh)
    src = metrics.source_skating(motion, map_motion(motion))
    if "optitrack" in shared_bvh.name:
        assert src["mean_cm_s"] >= 0.0
    else:
        assert src["mean_cm_s"] > 5.0, src


def _standing_targets(character, frames: int, spread: float):
    """Targets of the character's rest pose with the feet pulled apart by up to ``spread`` m."""
    from physmocap.ik.targets import Targets, character_rest_frames

    rest = character_rest_frames(character)
    names = tuple(rest)
    pos = np.array([rest[n][0] for n in names])
    quat = np.array([rest[n][1] for n in names])
    P = np.repeat(pos[None], frames, axis=0)
    Q = np.repeat(quat[None], frames, axis=0)
    ramp = np.linspace(0.0, spread, frames)
    for k, n in enumerate(names):
        if n.split("_", 1)[-1] in ("knee", "ankle", "toe", "toe_end"):
            P[:, k, 1] += ramp if n.startswith("left_") else -ramp
    has_q = np.array([n in ("pelvis", "chest", "head") for n in names])
    return Targets(names, P, Q, has_q, np.ones((frames, len(names)), bool), fps=60.0)


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_double_support_pulled_apart_stays_feasible_and_planted(character):
    from physmocap.ik.retarget import solve_targets
    from physmocap.models import load_character

    ch = load_character(character)
    frames = 60
    targets = _standing_targets(ch, frames, spread=0.25)
    labels = {k: np.ones(frames, bool) for k in ("left_heel", "left_toe", "right_heel", "right_toe")}
    traj = solve_targets(targets, ch, labels=labels, progress=False)
    assert np.all(traj.solver.relaxation == 0)  # every QP feasible with all constraints
    sites = [s for side in ("left", "right") for s in ch.contacts[side]]
    xy = traj.site_positions(sites)[:, :, :2]
    drift = np.linalg.norm(xy - xy[0], axis=-1).max()
    assert drift < 1e-3, f"a planted contact moved {drift * 1000:.2f} mm"
    # the feet stayed: the ankles end far from the actor's spreading targets
    raw = traj.targets.info["raw_positions"]
    k = traj.targets.index("left_ankle")
    ankle = traj.site_positions([ch.tracked["left_ankle"].name])[:, 0]
    assert np.linalg.norm(ankle[-1] - raw[-1, k]) > 0.1


def test_release_hands_back_without_a_pop():
    """After a long slide the swing foot rejoins its target smoothly (bounded per-frame change)."""
    from physmocap.ik.planting import FootAnchor

    fps = 120.0
    a = FootAnchor(fps, release_time=0.25)
    offs = []
    for t in range(120):
        down = t < 60
        target = np.array([0.01 * t, 0.0])  # the actor's foot slides 1.2 m/s while "down"
        offs.append(a.step(down, down, target, target, target if t == 0 else None, None))
    offs = np.array(offs)
    assert np.linalg.norm(offs[59]) > 0.5  # a large offset was built up...
    assert np.allclose(offs[-1], 0.0)  # ...and fully handed back,
    jumps = np.linalg.norm(np.diff(offs, axis=0), axis=1)
    assert jumps.max() < 0.6 * 1.2 * 2.5 / fps * 30  # smoothly: no single-frame pop


def test_a_foot_anchor_turns_with_its_holds_and_lets_go_from_where_the_foot_is():
    """FootAnchor.turn moves its anchors about the pivot, so the targets turn with a planted
    foot's holds; a foot let go fades its offset from where the character's ankle is (against
    the previous frame's target), not from where its anchor put the target."""
    from physmocap.ik.planting import FootAnchor

    a = FootAnchor(120.0, release_time=0.25)
    ankle, toe = np.array([0.0, 0.0]), np.array([0.1, 0.0])
    assert np.allclose(a.step(True, True, ankle, toe, ankle, toe), 0.0)
    a.turn(np.array([0.1, 0.0]), np.pi / 2)  # a quarter turn about the toe
    assert np.allclose(a.heel_anchor, [0.1, -0.1]) and np.allclose(a.toe_anchor, [0.1, 0.0])
    assert np.allclose(a.step(True, True, ankle, toe), [0.1, -0.1])  # the ankle's target turned along
    # let go with the ankle 3 cm short of where the anchor put its target: the first free frame's
    # offset starts there (0.03 off the previous frame's target), not at the anchor's
    now = ankle + np.array([0.13, -0.1])
    first = a.step(False, False, ankle, toe, now, toe)
    assert abs(first[0] - 0.13) < 0.01 and abs(first[1] + 0.1) < 0.01, first
    for _ in range(40):
        last = a.step(False, False, ankle, toe, now, toe)
    assert np.allclose(last, 0.0)


def test_stream_toe_of_a_foot_with_toes_lets_go_as_its_target_takes_off():
    """A toe segment bends as its target rises slowly (an actor rolling over his toes): its
    hold stays; a target rising faster than toe_release_speed (a take-off) lets it go
    (Planting._toes_moving, the target's speed in three dimensions)."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("humanoid")
    names = tuple(ch.tracked)
    fps = 120.0
    planting = Planting(ch, names, fps, anchored=True)
    assert not planting._rigid["left"]
    toe = names.index("left_toe")
    slow = 0.5 * planting.options.toe_release_speed / fps
    pos = np.zeros((len(names), 3))
    pos[toe] = [0.2, 0.0, 0.03]
    on_toes = {"left_heel": False, "left_toe": True}
    for _ in range(20):  # 2 cm up, slowly: held
        pos[toe, 2] += slow
        assert planting._toes_moving(pos, on_toes)["left_toe"]
    pos[toe, 2] += 3 * slow  # straight up, faster than the release speed: let go
    assert not planting._toes_moving(pos, on_toes)["left_toe"]


def test_stream_toe_lets_go_as_its_target_rises_off_the_floor():
    """A rigid foot's toe held alone lets go under its label once its target rises more than
    release_margin above its lowest since the toes alone are labelled (a take-off the causal
    label lags); not while its target stays down, and not while the heel is labelled
    (Planting._toes_moving)."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("robot")
    names = tuple(ch.tracked)
    planting = Planting(ch, names, 120.0, anchored=True)
    assert planting._rigid["left"]
    toe = names.index("left_toe")
    margin = planting.options.release_margin
    pos = np.zeros((len(names), 3))
    pos[toe] = [0.2, 0.0, 0.03]
    flat = {"left_heel": True, "left_toe": True}
    on_toes = {"left_heel": False, "left_toe": True}
    for _ in range(3):
        assert planting._toes_moving(pos, flat)["left_toe"]
    pos[toe, 2] += 2 * margin  # risen, the heel still labelled: held
    assert planting._toes_moving(pos, flat)["left_toe"]
    pos[toe, 2] -= 2 * margin  # and down again, still flat
    assert planting._toes_moving(pos, flat)["left_toe"]
    for _ in range(3):  # on the toes, the toe target down: held
        assert planting._toes_moving(pos, on_toes)["left_toe"]
    pos[toe, 2] += 0.5 * margin  # rising within the margin: held
    assert planting._toes_moving(pos, on_toes)["left_toe"]
    pos[toe, 2] += margin  # past it and rising: let go, until the label ends
    assert not planting._toes_moving(pos, on_toes)["left_toe"]
    assert not planting._toes_moving(pos, on_toes)["left_toe"]
    # a toe target that rose while the heel was still labelled (the CMU actor rolling onto his
    # toes, 1.2 cm) is where the toes stand: held while it stays there (before: let go the frame
    # the heel's label ended, and the robot's knee bent 8-18 degrees early at every push-off)
    again = Planting(ch, names, 120.0, anchored=True)
    pos[toe, 2] = 0.03
    for z in np.linspace(0.03, 0.042, 10):
        pos[toe, 2] = z
        assert again._toes_moving(pos, flat)["left_toe"]
    for _ in range(5):
        pos[toe, 2] += 0.0001
        assert again._toes_moving(pos, on_toes)["left_toe"]


def test_stream_heel_raised_in_place_lets_go():
    """A heel whose ankle target rises past engage_height + release_margin above its lowest in
    the contact lets go however slowly it moves (a heel raised in place; Planting._heels_moving)."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("robot")
    names = tuple(ch.tracked)
    planting = Planting(ch, names, 120.0, anchored=True)
    ankle = names.index("left_ankle")
    opt = planting.options
    labels = {"left_heel": True, "left_toe": True}
    pos = np.zeros((len(names), 3))
    pos[ankle] = [0.0, 0.0, 0.08]
    assert planting._heels_moving(pos, labels)["left_heel"]
    pos[ankle, 2] += 0.9 * (opt.engage_height + opt.release_margin)
    assert planting._heels_moving(pos, labels)["left_heel"]  # not yet past the band
    pos[ankle, 2] += 0.2 * (opt.engage_height + opt.release_margin)
    assert not planting._heels_moving(pos, labels)["left_heel"]


def test_toes_leave_the_floor_without_swinging_at_their_velocity_cap():
    """Toe-off (issue 9, "pops at toe-off"): the CMU actor rolls over its toe tips (its toe bone
    pitches with the foot).  Holding the character's toe segment flat until the label ended
    made the toes swing 90 degrees in a few frames at toe-off, at their velocity cap on 8 % of
    the walk's frames (4.6 % for one toe); the toe segment now keeps the actor's pitch, resting
    on its lowest point (physmocap.ik.footplan.ToeContact)."""
    from physmocap.metrics.fidelity import saturation_matrix

    _, traj = retargeted("cmu_12_01_walk.bvh", "humanoid")
    ch = traj.character
    limits = ch.velocity_limits
    sat = saturation_matrix(ch.model, traj.qpos, traj.fps, limits, ch.velocity_groups)
    names = list(limits)
    for side in ("left", "right"):
        share = float(sat[:, names.index(f"{side}_toe_extension")].mean())
        assert share < 0.025, (side, share)
    # the ankle does not pop up when the toes let go (it jumped 4 cm in one frame, 4.5 times the
    # actor's fastest vertical ankle speed): with the toes rolling its target is reachable
    ankle = traj.site_positions(["left_ankle", "right_ankle"])
    vz = np.abs(np.diff(ankle[..., 2], axis=0)) * traj.fps
    T = traj.targets
    actor = T.info["raw_positions"][:, [T.names.index("left_ankle"), T.names.index("right_ankle")], 2]
    actor_vz = np.abs(np.diff(actor, axis=0)) * traj.fps
    assert vz.max() < 2.0 * actor_vz.max(), (vz.max(), actor_vz.max())


@pytest.mark.parametrize("character", ["humanoid", "robot"])
def test_a_flat_foot_stands_flat(character):
    """Where the actor's foot is flat (heel and toes labelled), the character's is too.
    A second point of a foot used to be held from 1.4 cm up (or a toe tip in its landing
    bend): two held points fix the foot's tilt, so the heel (or toes) stayed 1.2-1.7 cm up
    for the whole stance on 96 % of the walk's flat-foot frames, the height pulls fighting
    the holds, and the knee bent to make up for it."""
    _, traj = retargeted("cmu_12_01_walk.bvh", character)
    flat = metrics.character_flat_feet(traj, traj.contacts)  # the highest contact site of a flat foot
    assert flat["contact_samples"] > 100
    assert flat["median_mm"] < 2.0, flat
    assert flat["share_over_band"] < 0.05, flat  # more than 1 cm up (it was 96 %)


def test_a_second_hold_of_a_rigid_foot_starts_at_its_flat_rest_distance():
    """FootPlanter._anchor_for: with the ball held, the heel is held at the ball's anchor plus
    the heel-to-ball distance of the flat rest pose, in the current heel direction."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("humanoid")
    names = list(ch.rest_positions())
    planting = Planting(ch, names, 30.0, anchored=False)
    locks = planting.locks
    heel, ball = locks.sites.index("right_heel"), locks.sites.index("right_ball")
    rest = locks.rest_distances[heel, ball]
    assert 0.1 < rest < 0.3
    assert np.isnan(locks.rest_distances[heel, locks.sites.index("right_toe_tip")])  # toes may bend
    locks.locked[ball] = True
    locks.anchor[ball] = [1.0, 2.0, 0.0]
    tilted = np.array([1.0 - 0.99 * rest, 2.0])  # a heel still up: its foot's extent is shorter
    a = locks._anchor_for(heel, tilted)
    assert np.isclose(np.linalg.norm(a - [1.0, 2.0]), rest)
    assert np.allclose((a - [1.0, 2.0]) / rest, [-1.0, 0.0])
    locks.locked[ball] = False
    assert np.allclose(locks._anchor_for(heel, tilted), tilted)  # a foot's first hold: where it is


@pytest.mark.parametrize("clip", ["cmu_12_01_walk.bvh", "pymo_walk.bvh"])
def test_joints_do_not_chatter_at_their_velocity_caps(clip):
    """The smoothness prior (SolverOptions.smoothness_cost): without it the solver wandered in
    directions the tasks barely see (the PyMO walk's spine against its clavicles alternated by
    5 degrees from frame to frame) and some joint sat at its velocity cap on 3.1 % (CMU walk)
    and 3.5 % (PyMO) of the frames."""
    _, traj = retargeted(clip, "humanoid")
    fid = traj.fidelity
    assert fid.saturated_share < 0.015, (fid.saturated_share, fid.saturated_joint)
    assert fid.saturated_joint_share < 0.01, (fid.saturated_joint_share, fid.saturated_joint)


def test_flat_feet_figure_takes_a_label_file_without_every_point():
    """metrics.character_flat_feet: a contact-label file that leaves a point out (no
    left_toe here) measures the other foot instead of failing on the missing key."""
    _, traj = retargeted("cmu_12_01_walk.bvh", "humanoid")
    contacts = traj.contacts
    full = metrics.character_flat_feet(traj, contacts)
    kept = dict(contacts.labels)
    try:
        contacts.labels = {k: v for k, v in kept.items() if k != "left_toe"}
        partial = metrics.character_flat_feet(traj, contacts)
    finally:
        contacts.labels = kept
    assert 0 < partial["contact_samples"] < full["contact_samples"]


@pytest.mark.parametrize("clip", ["cmu_12_01_walk.bvh", "pymo_walk.bvh"])
def test_the_ball_stays_where_it_rests_while_the_foot_rolls_over_its_toes(clip):
    """Before: while only the toes were down, the humanoid's ball (on the foot body, 2.3 cm
    below the toe joint) was let go and slid round the toe joint as the heel rose: 7.9 cm/s
    (CMU walk) and 5.4 cm/s (PyMO walk) mean while within 5 mm of the floor.  Now it is held
    where it rests, not pulled down, until it lifts (PlanHints.lifting): 0.4 and 2.5 cm/s; 3.1
    on the PyMO walk since a frame far from its targets gets more iterations (catch_up), which
    let its foot roll a little further on the frames the ball is held; 3.7 since a toe tip
    tipped onto the end of its capsule is held on that end (FootPlanter._follow_contact): a
    foot turned with the actor's turns its held ball about that end, 3 cm further off than the
    tip's site (the PyMO walk's frames 904-906, 8-11 cm/s; the foot's slip, pivots excepted,
    0.77 -> 0.30 cm/s)."""
    _, traj = retargeted(clip, "humanoid")
    labels, speeds = traj.contacts.labels, []
    for side in ("left", "right"):
        pos = traj.site_positions([traj.character.contacts[side][1]])[:, 0]
        rolling = labels[f"{side}_toe"] & ~labels[f"{side}_heel"]
        low = pos[:, 2] < 0.005
        both = rolling[1:] & rolling[:-1] & low[1:] & low[:-1]
        speeds.append(np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=1)[both] * traj.fps * 100.0)
    speeds = np.concatenate(speeds)
    assert speeds.size > 10 and speeds.mean() < 4.2, (speeds.size, speeds.mean())


def test_a_lost_toe_target_does_not_let_a_streamed_toe_go():
    """A stream's toe target lost for a few frames comes back from its stand-in position in
    one jump (23 m/s on a CMU walk stream): that is no motion of the actor's toe, and the
    toe held alone must not be let go for it (Planting._toes_moving)."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character()
    names = tuple(ch.tracked)
    planting = Planting(ch, names, 120.0, anchored=True)
    toe = names.index("left_toe")
    labels = {"left_heel": False, "left_toe": True}
    positions = np.zeros((len(names), 3))
    valid = np.ones(len(names), dtype=bool)
    assert planting._toes_moving(positions, labels, valid)["left_toe"]
    lost = valid.copy()
    lost[toe] = False
    moved = positions.copy()
    moved[toe, :2] = [0.15, 0.13]  # the stand-in, then the toe found again: a jump
    assert planting._toes_moving(moved, labels, lost)["left_toe"]
    assert planting._toes_moving(positions, labels, valid)["left_toe"]
    faster = positions.copy()
    faster[toe, 0] += 0.02  # 2.4 m/s between two tracked frames: the actor's toe is off
    assert not planting._toes_moving(faster, labels, valid)["left_toe"]


def test_stream_heel_lets_go_when_its_target_lifts_and_rolls_on():
    """A stream's heel is let go at push-off: once its ankle target has risen above its lowest
    in the contact and moves on faster than heel_release_speed, under its (lagging) label or
    after it; a heel whose target slides without lifting (a shuffle) stays held, and a new
    contact starts afresh (Planting._heels_moving)."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("robot")
    names = tuple(ch.tracked)
    fps = 120.0
    planting = Planting(ch, names, fps, anchored=True)
    ankle = names.index("left_ankle")
    step = planting.options.heel_release_speed / fps * 1.5  # faster than the release speed
    labels = {"left_heel": True, "left_toe": True}
    pos = np.zeros((len(names), 3))
    pos[ankle] = [0.0, 0.0, 0.08]
    for _ in range(3):  # standing
        assert planting._heels_moving(pos, labels)["left_heel"]
    for _ in range(3):  # sliding flat: held
        pos[ankle, 0] += step
        assert planting._heels_moving(pos, labels)["left_heel"]
    pos[ankle, 2] += 2 * planting.options.release_margin  # lifted: a move now lets it go
    assert planting._heels_moving(pos, labels)["left_heel"]  # lifted, not moving yet
    pos[ankle, 0] += step
    assert not planting._heels_moving(pos, labels)["left_heel"]
    pos[ankle, 0] += 0.001  # slowing down, the label still on: still let go
    assert not planting._heels_moving(pos, labels)["left_heel"]
    off = {"left_heel": False, "left_toe": False}
    assert not planting._heels_moving(pos, off)["left_heel"]
    pos[ankle] = [0.3, 0.0, 0.08]  # a new contact
    assert planting._heels_moving(pos, labels)["left_heel"]
    # after its label, a heel still held low lets go as its target lifts and moves on
    pos[ankle, 2] += 2 * planting.options.release_margin
    planting._heels_moving(pos, off)
    pos[ankle, 0] += step
    planting._heels_moving(pos, off)
    assert planting._heel_watch["left"].gone
    disabled = Planting(ch, names, fps, dataclasses.replace(planting.options, heel_release_speed=0.0), anchored=True)
    assert disabled._heels_moving(pos, labels) == labels


def _right_toe_hold(character: str):
    """``(character, its offline planter's FootPlanter, the index of the right foot's last contact
    site there, that site's body)``."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character(character)
    locks = Planting(ch, list(ch.rest_positions()), 120.0, anchored=False).locks
    k = locks.sites.index(ch.contacts["right"][-1])
    return ch, locks, k, int(ch.model.site(locks.sites[k]).bodyid[0])


def test_a_rigid_foot_tipped_onto_a_corner_is_held_on_that_corner():
    """FootPlanter._follow_contact: a rigid foot rolling over its front edge is held at its
    pivot site while the edge is level; tipped onto one corner (an ankle roll at its limit),
    it is held on that corner where it rests, so it turns about the corner instead of
    dragging it (the robot's toe-offs on the PyMO walk dragged the corner 1-3 mm a frame);
    a foot still coming down is not tipped."""
    import mujoco

    from physmocap.ik.planting import PlanHints
    from physmocap.ik.tasks import BodyPointTask, SitePositionTask
    from physmocap.models.geometry import character_geoms, geom_z_extent

    ch, locks, toe, foot = _right_toe_hold("robot")
    model = ch.model
    geoms = [g for g in character_geoms(model, collision_only=True) if model.geom_bodyid[g] == foot]
    data = ch.rest_data()

    def pose(pitch: float, roll: float, lift: float = 0.0) -> float:
        """The rest pose with the right ankle turned, lowered onto the floor (+ ``lift``)."""
        mujoco.mju_copy(data.qpos, ch.rest_data().qpos)
        data.qpos[model.joint("r_ankle_pitch").qposadr[0]] = pitch
        data.qpos[model.joint("r_ankle_roll").qposadr[0]] = roll
        mujoco.mj_kinematics(model, data)
        low = min(geom_z_extent(model, data, g)[0] for g in geoms)
        data.qpos[2] += lift - low
        mujoco.mj_kinematics(model, data)
        return low

    flags = np.zeros(len(locks.sites), dtype=bool)
    flags[toe] = True
    pivoting = flags.copy()
    hints = PlanHints(rolling=np.zeros_like(flags), holdable=np.ones_like(flags), pivoting=pivoting)

    def hold():
        _, hard, _ = locks.update(flags, data, hints)
        (task,) = [t for t in hard if getattr(t, "site_id", None) == model.site(locks.sites[toe]).id
                   or getattr(t, "body", None) == foot]
        return task

    pose(0.0, 0.0)  # flat: held at the site
    assert isinstance(hold(), SitePositionTask)
    pose(np.radians(8.0), 0.0)  # heel up, front edge level on the floor: still the site
    assert isinstance(hold(), SitePositionTask)
    pose(np.radians(8.0), np.radians(15.0))  # tipped onto one corner
    task = hold()
    assert isinstance(task, BodyPointTask)
    corner = task.point(data)
    assert abs(corner[2]) < 1e-6  # the corner it stands on
    assert np.allclose(task.target[:2], corner[:2])
    site = data.site_xpos[model.site(locks.sites[toe]).id]
    assert site[2] > 0.005  # its pivot site is off the floor
    assert hold() is task and np.allclose(task.target[:2], corner[:2])  # held where it rests
    pose(np.radians(8.0), 0.0)  # level again: back on the site, where it is
    task = hold()
    assert isinstance(task, SitePositionTask)
    assert np.allclose(task.target[:2], data.site_xpos[task.site_id, :2])
    pose(np.radians(8.0), np.radians(15.0))
    assert isinstance(hold(), BodyPointTask)
    pose(np.radians(8.0), np.radians(15.0), lift=0.004)  # tipped, but off the floor: the site
    assert isinstance(hold(), SitePositionTask)


def test_toes_bend_through_toe_off_without_snapping_at_their_cap():
    """While only the toes are down, the ball's hold and the toe tip's lock the toes' bend;
    a hard hold let go at its top left the toes to catch up at their velocity cap (the CMU
    walk's right toe, 35 degrees in three frames at 413-414, and a hold taken again as the
    bending toes lowered the ball at 265).  The ball's hold now lets go softly as it rises:
    no joint of the humanoid sits at its cap on more than 0.5 % of the walk (the issue's
    bound), and the toes never on two frames running (their largest step, about 12 degrees
    at toe-off, is one frame at 0.90-1.0 of the cap: where in that band depends on the rest
    of the body's solution, e.g. the head's calibration, stop 31)."""
    from physmocap.metrics.fidelity import saturation_matrix

    _, traj = retargeted("cmu_12_01_walk.bvh")
    ch = traj.character
    sat = saturation_matrix(ch.model, traj.qpos, traj.fps, ch.velocity_limits, ch.velocity_groups)
    names = list(ch.velocity_limits)
    share = sat.mean(axis=0)
    assert share.max() <= 0.005, {names[j]: round(float(share[j]), 4) for j in np.flatnonzero(share > 0.005)}
    toes = [j for j, n in enumerate(names) if "toe" in n]
    running = sat[1:, toes] & sat[:-1, toes]
    assert not running.any(), [names[toes[j]] for j in np.flatnonzero(running.any(axis=0))]


def test_a_toe_tip_tipped_onto_the_end_of_its_capsule_is_held_there():
    """A foot with toes standing on them alone (offline, ``rolling``): its toe-tip site is held
    while the toes rest level; rolled (an inverted foot on its toes, a dancer's turn), the
    toe segment's capsule rests on one end, the site is off the floor, and the hold moves to
    the end it rests on (FootPlanter._follow_contact, as a rigid foot's corner).  Held at the
    site, the foot turned about it and swept the resting end round over the floor: the CMU
    dance's humanoid slipped 1.01 cm/s (its spins on the toes, frames 140-160 and 720-775;
    0.42 now)."""
    import mujoco

    from physmocap.ik.planting import PlanHints
    from physmocap.ik.tasks import BodyPointTask, SitePositionTask
    from physmocap.models.geometry import character_geoms, geom_z_extent

    ch, locks, tip, toes = _right_toe_hold("humanoid")
    model = ch.model
    foot = {toes, int(model.body_parentid[toes])}
    geoms = [g for g in character_geoms(model, collision_only=True) if model.geom_bodyid[g] in foot]
    data = ch.rest_data()

    def pose(roll: float, lift: float = 0.0) -> None:
        """Heel up 29 degrees, toes bent as much (they lie level), the foot inverted by ``roll``,
        lowered onto the floor (+ ``lift``)."""
        mujoco.mju_copy(data.qpos, ch.rest_data().qpos)
        data.qpos[model.joint("right_ankle_dorsiflexion").qposadr[0]] = -0.5
        data.qpos[model.joint("right_toe_extension").qposadr[0]] = 0.5
        data.qpos[model.joint("right_ankle_inversion").qposadr[0]] = roll
        mujoco.mj_kinematics(model, data)
        data.qpos[2] += lift - min(geom_z_extent(model, data, g)[0] for g in geoms)
        mujoco.mj_kinematics(model, data)

    flags = np.zeros(len(locks.sites), dtype=bool)
    flags[tip] = True
    hints = PlanHints(rolling=flags.copy(), holdable=np.ones_like(flags))

    def hold():
        _, hard, _ = locks.update(flags, data, hints)
        (task,) = [t for t in hard if getattr(t, "site_id", None) == model.site(locks.sites[tip]).id
                   or getattr(t, "body", None) == toes]
        return task

    pose(0.0)  # on the toes, level: held at the site
    assert isinstance(hold(), SitePositionTask)
    pose(0.25)  # rolled 14 degrees: on one end of the capsule
    task = hold()
    assert isinstance(task, BodyPointTask)
    end = task.point(data)
    assert abs(end[2]) < 1e-6 and np.allclose(task.target[:2], end[:2])
    site = data.site_xpos[model.site(locks.sites[tip]).id]
    assert site[2] > 0.005 and np.linalg.norm(site[:2] - end[:2]) > 0.02  # the site is off the floor, to the side
    pose(0.0)  # level again: back on the site, where it is
    task = hold()
    assert isinstance(task, SitePositionTask)
    assert np.allclose(task.target[:2], data.site_xpos[task.site_id, :2])
    pose(0.25, lift=0.004)  # rolled, but still coming down: the site
    assert isinstance(hold(), SitePositionTask)


def test_a_held_toe_tip_keeps_a_soft_hold_until_the_landing_heel_is_held():
    """Offline, the toes of a flat foot are not held (its heel and ball fix it), so a toe tip
    lets go once the heel is labelled.  But the heel is held only once it is down, and at
    30 fps it is often labelled a frame before: for that frame nothing held the foot, and it
    slid over the floor towards its plan (the Bandai punch: 1-5 cm in one frame).  A toe tip
    held when the heel is labelled keeps its hold, softly, until the heel is held
    (``PlanHints.soft``); then it lets go."""
    from physmocap.ik.planting import Planting
    from physmocap.models import load_character

    ch = load_character("humanoid")
    names = tuple(ch.rest_positions())
    planting = Planting(ch, names, 30.0, anchored=False)
    data = ch.rest_data()  # standing on the floor: every contact site down
    rest = np.array([ch.rest_positions()[n] for n in names])
    tip_id, heel_id = (int(ch.model.site(s).id) for s in (ch.contacts["right"][-1], ch.contacts["right"][0]))

    def holds(right_heel: bool) -> tuple[bool, bool, bool]:
        """(tip held hard, tip held softly, heel held hard) on the next frame."""
        labels = {"left_heel": True, "left_toe": True, "right_heel": right_heel, "right_toe": True}
        _, soft, hard, _ = planting.step(rest, labels, data)
        on = lambda tasks, i: any(getattr(t, "site_id", None) == i and t.axes == (0, 1) for t in tasks)  # its horizontal hold
        return on(hard, tip_id), on(soft, tip_id), on(hard, heel_id)

    assert holds(False) == (True, False, False)  # on the toes: the tip held, the heel free
    assert holds(True) == (False, True, True)  # the heel labelled and caught: the tip held softly
    assert holds(True) == (False, False, True)  # the heel held: the tip lets go
