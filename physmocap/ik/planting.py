"""Foot planting: contact points hold still on the floor while their foot is in contact.

Three causal pieces (each frame uses only its own contact labels and the
previous frame's solution, so offline and streaming retargeting share them),
combined by :class:`Planting`:

* :class:`FootPlanter`, per contact site (heel, ball, toe tip ...):

  - a labelled site is pulled onto the floor by a soft height task
    (``cost_z``, ramped in over ``onset_time``, descending at most
    ``max_descent_speed``), so a foot labelled down while still in the air
    lands over a few frames instead of slamming down;
  - a site is *held* (its horizontal position a hard equality of the QP,
    mink ``constraints=``) from the frame a labelled site touches down
    (within ``engage_height`` of the floor) until it has lifted clear again
    (``engage_height + release_margin``), label or not, so a foot rises before
    it moves: that is what keeps the stance-band speed near zero;
  - offline, a rigid foot tipped onto one corner of its edge is held on that corner
    (:meth:`FootPlanter._follow_contact`);
  - a foot held at two points or more turns its holds towards the actor's foot heading
    (:mod:`.footturn`, :meth:`FootPlanter.turn`) about its most distal held point resting
    on the floor, so an actor pivoting on a planted foot is followed;
  - sites of a foot that is neither labelled nor held get a swing clearance
    (a hard inequality, :class:`~physmocap.ik.limits.FloorLimit`), so a swing
    foot does not skim, and slide within, the stance band.

* :class:`FootAnchor`, per foot: the foot's *targets* are offset so that they
  stand still while it is in contact (the actor's own feet slide, and so do
  targets built for other proportions), anchored where the character's foot
  actually landed, and the offset is handed back along a smoothstep over
  ``anchor_release_time`` after release.  The knee target is re-solved by
  two-bone IK so thigh and shank keep their lengths.

* The body follows its planted feet: a root offset relaxes (time constant
  ``root_follow_time``) towards the mean offset of the held feet, so a source
  whose feet slide does not stretch the stance leg and drag the pelvis.  Swing
  feet hand back to this root offset rather than to zero, less ``drift_correction``
  towards zero, so each step lands a little nearer the actor's path and the body,
  following, does not drift away from it for good.

If holding a site makes a QP infeasible (velocity limits, joint limits), the
solver's first relaxation softens the equalities into tasks of cost
``cost_xy`` (see :mod:`physmocap.ik.solver`).  All positions are metres in the
character's world (Z-up, floor at ``floor``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import mujoco
import numpy as np

from ..metrics.fidelity import RESTING_HEIGHT  # a hold that let go softly is taken hard again within it
from ..models.geometry import character_geoms, foot_bodies, geom_candidates
from ..errors import OptionError
from ..options import check_fields
from .footplan import FOOT_JOINTS, RigidFoot, ToeContact, knee_between
from .easing import smoothstep
from .footturn import HeadingFollower
from .targets import character_rest_frames
from .tasks import BodyPointTask, SitePositionTask

__all__ = ["PlantOptions", "PlanHints", "FootPlanter", "FootAnchor", "Planting"]

#: Metres a rigid foot's pivot site may stand higher over the foot's lowest point than in the
#: rest pose before the foot counts as tipped, and the lowest point's height above the floor
#: beyond which the foot is still coming down (:meth:`FootPlanter._follow_contact`).
TIP_HEIGHT = 0.002
#: Metres within the lowest that a material point of a foot still rests (its resting patch:
#: a box's bottom edge or corner; as the figures' contact patch).
PATCH_TIE = 0.001
#: Metres a tipped foot's resting patch may move on the foot before its hold moves with it.
PATCH_MOVE = 0.005
#: Seconds from the start of a heel's label over which a toe tip held as it starts keeps a soft
#: hold while the heel is not held yet (:meth:`Planting.step`): a heel is labelled up to a
#: frame of a 30 fps clip before it is down.  Longer, a heel labelled while the actor's foot
#: rose 3 cm (the Bandai punch, frames 172-176) kept the foot on the floor.
LANDING_HOLD_TIME = 0.04


@dataclass
class PlantOptions:
    """Planting options.

    Attributes:
        plant: Enable planting at all.
        cost_xy: Cost per metre of the horizontal lock when the solver has to
            soften it (it is a hard equality otherwise).
        cost_z: Cost per metre of the height task pulling a labelled site onto the floor.
        onset_time: Seconds over which the height cost ramps in at contact start.
        anchor_release_time: Seconds over which a foot's target offset
            (:class:`FootAnchor`) fades back to the actor's motion after release.
        lock_low: Streaming only: keep holding a site after its label ends until it
            has lifted clear of ``engage_height + release_margin`` (False: let go with
            the label).  Offline the labels are final and sites are held exactly
            while labelled.
        toe_release_speed: Streaming only: a toe held alone (heel up) lets go, until its
            label ends, once its target moves faster than this (m/s; in three dimensions, so
            a take-off straight up counts): a causal label ends 50-70 ms after the foot has
            left the floor (:meth:`Planting._toes_moving`; after the label, horizontally).
            Half the contact detector's default ``toe_speed_exit``, which the detector acts on
            only after ``min_gap``: at that speed (0.8, until stop 38) a robot's rigid foot
            stayed pinned by its tip at push-off while the actor's ankle rose and moved 10-20
            cm on, its thigh 20-40 degrees behind the actor's (the streamed CMU walk's worst segment 8.8 degrees,
            3.8 at 0.4; 6.0 at 0.6, 4.1 at 0.5, 3.9 at 0.3).
        heel_release_speed: Streaming only: a heel lets go, until its label begins again,
            once its ankle target has risen ``release_margin`` above its lowest in the contact
            and moves horizontally faster than this (m/s): the heel lifting at push-off, its
            causal label still on or its sites still held low (:meth:`Planting._heels_moving`);
            and whatever its speed once it has risen ``engage_height + release_margin``.
            0: never.
        engage_height: Height (metres) below which a labelled site is held:
            above the 1 cm stance band of the quality metrics and above
            ``clearance``, so a swing foot held at its clearance is held as
            soon as its contact begins.
        release_margin: A held site is let go only above ``engage_height`` plus this.  A
            site held next to a held point of another segment (a ball next to a held toe
            tip: the two fix the toes' bend) lets go softly instead, its hold's cost fading
            along a smoothstep as it rises through this margin above ``settle_height``
            (:meth:`FootPlanter.update`).
        settle_height: A site whose foot is already held at a point of another segment
            (a toe tip next to a held ball) is held only while it is this close to the
            floor (metres; a hold left above it, from toes rolling, is let go until the
            site settles).  Two held points fix the toes' bend: a tip held where it first
            touched, 1.4 cm up, kept a standing actor's toes bent and, through their height
            pull, the heels 1.3 cm up for 20 s.  Held from this height the bend it can
            lock is under :math:`\\arcsin(h/L)`: 7 degrees for 4 cm toes, and its tip
            then rests on the floor.  (A further point of the *same* segment is held from
            ``engage_height``, without look-ahead, at its flat rest distance:
            :meth:`FootPlanter._anchor_for`.)
        clearance: Swing feet (contact sites neither labelled nor held) stay
            at least this high (metres), a hard inequality (0 disables): a foot
            skimming the floor would otherwise slide within the stance band.  Under
            a rigid foot (no toe joint) the geoms' clearance eases out over the whole
            frames of ``onset_time`` once the foot lands, as its height pull eases in
            (:meth:`FootPlanter.clearance_share`).
        max_descent_speed: Fastest a labelled site is pulled down (m/s).
        root_follow_time: Streaming only: time constant (s) with which the whole
            body follows the mean offset of its planted feet from the actor's
            path (0: the body keeps the actor's path and only the feet are
            offset).  Offline retargeting never moves the body
            (:mod:`physmocap.ik.footplan`).
        drift_correction: Streaming only: metres by which a swing foot's target offset is
            handed back nearer the actor's path than the body's root offset (its size less
            this, at most to none), so each step lands up to that much closer and the body,
            following its feet, comes back to the actor's path instead of keeping every
            offset it ever took (feet anchored where they land behind their targets, the body
            following them: the streamed PyMO walk's pelvis drifted a mean 15 cm from the
            actor's scaled path, the robot's 24; with 3 cm, 5 and 11).  5 cm took the drift
            further (3 and 7) but made the CMU jumps' streamed robot slip 1.13 cm/s and face
            9 degrees off (p95) where the actor lands from its jumps.  0: none.
        ease_time: Offline only: seconds over which a foot's plant offset eases
            in before a contact and out after it (:mod:`physmocap.ik.footplan`).
        pivot_cost: Offline only: cost per metre of the pull that keeps a rigid
            foot's toe site (no toe joint) on the floor while the foot rolls over
            its front edge, a tenth of ``cost_z``: without it the foot could tip
            onto its side edge instead of pitching (measured on the bundled robot:
            25 degrees of roll, its ankle roll limit, and 11 cm/s of slip).
        pivot_threshold: Radians a foot held at two points may be off its
            target heading before its holds turn (:mod:`.footturn`: beyond it they follow
            the target's heading, so an actor pivoting on a planted foot is followed; within
            it the difference is taken as the capture's drift and the foot stays put).  2
            degrees, measured on the shared clips (whose flat feet drift by a median 1.4-6.5
            degrees over a stance; a spin turns one by 30 degrees and more): against 5
            degrees it follows the dance better (worst segment 8.3 -> 7.5 degrees, the
            robot's facing on the jumps' turn p95 8.3 -> 5.8) with the feet's slip about
            the same (heels swivel more about the ball: the PyMO walk's geom slip 1.3 ->
            2.1 cm/s); against 0 it keeps the walks' heels from swivelling with every
            degree of drift (PyMO geom slip 2.1 against 3.2 cm/s).  Streaming uses 10
            degrees (:data:`~physmocap.ik.stream.STREAMING_DEFAULTS`: it cannot tell a
            wobble from the start of a pivot).
        heading_rate: Radians per second at which a held foot's heading
            error beyond ``pivot_threshold`` that the target's own turning does not explain
            (a foot caught off its heading as it landed) is taken out (:mod:`.footturn`).
        smooth_transitions: Offline only: retarget once more with the joints pulled towards
            their own low-pass around every contact change (:mod:`physmocap.ik.transitions`),
            so that what a hold kept back does not catch up in one frame when it lets go.
        transition_window: Offline only: seconds either side of a contact change over which
            the last pass pulls.
        transition_sigma: Offline only: standard deviation (seconds) of the Gaussian
            low-pass the last pass pulls towards (2 frames at 120 Hz).
        transition_cost: Offline only: cost per radian (metre) of that pull (the arm
            passes' guide weighs the same; the position tasks 5 per metre).
        transition_tolerance: Offline only: metres; a joint is not pulled on a frame where
            the low-pass moves a target it carries by more than this (the actor's own fast
            motion, which the pull would lag).
    """

    plant: bool = True
    cost_xy: float = 400.0
    cost_z: float = 400.0
    onset_time: float = 0.03
    anchor_release_time: float = 0.25
    lock_low: bool = True
    engage_height: float = 0.014
    release_margin: float = 0.006
    settle_height: float = 0.005
    clearance: float = 0.012
    max_descent_speed: float = 1.0
    root_follow_time: float = 0.15
    drift_correction: float = 0.03
    ease_time: float = 0.1
    pivot_cost: float = 40.0
    pivot_threshold: float = 0.035
    heading_rate: float = 1.0
    toe_release_speed: float = 0.4
    heel_release_speed: float = 0.4
    smooth_transitions: bool = True
    transition_window: float = 0.1
    transition_sigma: float = 0.0167
    transition_cost: float = 2.0
    transition_tolerance: float = 0.01

    def __post_init__(self) -> None:
        check_fields(self, "planting")
        if self.transition_sigma > MAX_TRANSITION_SIGMA:
            # the low-pass's kernel and the frames it reads grow with it (an hour-long sigma would
            # read the whole clip into memory); a contact change's catch-up lasts a few frames
            raise OptionError(
                f"planting option transition_sigma must be at most {MAX_TRANSITION_SIGMA:g} s, got {self.transition_sigma!r}"
            )


#: Seconds: the largest ``PlantOptions.transition_sigma`` (about 60 times the default).
MAX_TRANSITION_SIGMA = 1.0

#: Pitch (radians) of a foot's ankle-to-toe targets beyond which its heading is not read
#: (:class:`~.footturn.HeadingFollower`): at 60 degrees the horizontal part is half the bone.  (A
#: streamed foot, still held as it pitched through its toe-off, read heading steps of 20-90
#: degrees a frame on the PyMO walk; the stream does not turn its holds yet.)
HEADING_PITCH = np.radians(60.0)

#: Metres: a foot whose first and last contact sites lie closer than this horizontally in the
#: rest pose has no heading to turn its holds by (:class:`~.footturn.HeadingFollower`).
MIN_HEADING_SPAN = 0.02


@dataclass(frozen=True)
class PlanHints:
    """What the offline plan says about each contact site this frame (sites in planter order).

    Attributes:
        rolling: The site's height is planned by the targets (a toe segment rolling
            with the actor's, :mod:`.footplan`): held horizontally while labelled,
            whatever its height, and not pulled down; tipped onto the end of its geom,
            held on that end (:meth:`FootPlanter._follow_contact`).
        holdable: The site may be held (the others are only pulled down).
        lifting: The site is held horizontally while it stays down but not pulled
            down: the ball of a foot rolling over its toes, which rests where it is
            while the heel rises and lifts as the toes bend (None: no such site).
        pivoting: The site is the front edge of a rigid foot rolling over it, held while
            labelled whatever its height (pulled down only softly, it may rise: let go
            2 cm up while its label still held the foot, the PyMO walk's robot foot slid
            3.3 cm in one frame).  None: no such site.
        bending: The site's foot's toe targets bend up on this frame (the toe segment's
            pitch above the foot's grows): a ball held next to its held toe tip may let go
            softly (:meth:`FootPlanter.update`).  None: unknown (never lets go softly).
        released: Streaming: the site lets go with its label instead of staying held while
            low (``PlantOptions.lock_low``): the heel of a foot rolling over its toes (held
            with its ball, two holds on one rigid body keep the foot flat, and a trailing leg
            with a flat foot drags the pelvis down) and every site of a foot whose toe has let
            go (:meth:`Planting._toes_moving`: the foot lifts as a whole instead of its ball
            staying held while the toes sweep forward over the floor).  None: no such site.
        soft: The site's hold is soft this frame: a toe tip held when its heel is labelled,
            until the heel is held (:meth:`Planting.step`).  None: no such site.
    """

    rolling: np.ndarray
    holdable: np.ndarray
    lifting: np.ndarray | None = None
    pivoting: np.ndarray | None = None
    bending: np.ndarray | None = None
    released: np.ndarray | None = None
    soft: np.ndarray | None = None


class FootPlanter:
    """Lock state of every contact site, turned into IK tasks frame by frame."""

    def __init__(
        self,
        model: mujoco.MjModel,
        sites: Sequence[str],
        fps: float,
        options: PlantOptions | None = None,
        floor: float = 0.0,
        rest_distances: np.ndarray | None = None,
        feet: Sequence[int] | None = None,
        rest_gaps: np.ndarray | None = None,
    ) -> None:
        self.options = opt = options or PlantOptions()
        self.model = model
        self.sites = tuple(sites)
        self.floor = float(floor)
        #: ``(n, n)`` horizontal distance (metres) between two sites of the same foot
        #: standing flat in the rest pose; NaN between feet (:meth:`_anchor_for`)
        self.rest_distances = rest_distances
        #: ``(n,)`` which foot each site belongs to (None: every site is its own foot)
        self.feet = np.arange(len(self.sites)) if feet is None else np.asarray(feet, dtype=int)
        self.tasks = [SitePositionTask(model, s, cost=0.0, axes=(2,)) for s in self.sites]
        self.xy = [SitePositionTask(model, s, cost=opt.cost_xy, axes=(0, 1)) for s in self.sites]
        #: ``(n,)`` each site's height (metres) over its body's lowest material point in the
        #: rest pose (NaN: a body without collision geoms); None: no tipped-foot holds
        self.rest_gaps = rest_gaps
        #: per site, the hold of the corner its tipped foot rests on (:meth:`_follow_contact`)
        self.corner = [BodyPointTask(model, int(model.site(s).bodyid[0]), cost=opt.cost_xy, axes=(0, 1))
                       for s in self.sites]
        #: sites whose hold is on their foot's resting corner this frame, not on the site
        self.on_corner = np.zeros(len(self.sites), dtype=bool)
        self._prev_z: np.ndarray | None = None
        n = len(self.sites)
        self.locked = np.zeros(n, dtype=bool)
        #: per held site, the share of its hold's cost while it lets go (1: a hard hold)
        self.fade = np.ones(n)
        self.age = np.zeros(n, dtype=int)
        self.labelled = np.zeros(n, dtype=bool)
        #: sites neither labelled nor held this frame (they get the swing clearance)
        self.free = np.zeros(n, dtype=bool)
        #: sites that have been down since their foot last swung (a heel lifting off over its
        #: toes has; a toe still coming down after its heel has not)
        self.landed = np.zeros(n, dtype=bool)
        self.fps = float(fps)
        self.onset_frames = max(1, int(round(opt.onset_time * fps)))
        #: whole frames within ``onset_time`` (none at 30 fps): a landing foot's clearance eases
        #: out over them (:meth:`clearance_share`)
        self.clearance_frames = int(opt.onset_time * fps + 1e-9)
        #: per foot, frames since it landed from its last swing (0: swinging; a foot down from
        #: the first frame counts as landed long ago)
        self.landing = np.full(int(self.feet.max()) + 1 if n else 0, self.clearance_frames + 1, dtype=int)
        self.anchor = np.zeros((n, 3))
        #: sites whose hold is soft on this frame: a foot turning about another held site
        #: (:meth:`turn`; a hard hold turned with the plan could be out of the leg's reach)
        self.turning = np.zeros(n, dtype=bool)
        self._site_ids = np.array([t.site_id for t in self.tasks], dtype=int)
        #: per site, the sites of its foot it has a rest distance to (a rigid foot's)
        self._rest_partners = None if rest_distances is None else np.isfinite(rest_distances)
        #: per site, the other sites of its foot (its possible partners in a hold)
        self._others = (self.feet[:, None] == self.feet[None, :]) & ~np.eye(n, dtype=bool)
        #: per foot, its sites
        self._foot_sites = [(int(f), self.feet == f) for f in np.unique(self.feet)]

    def _anchor_for(self, k: int, xy: np.ndarray) -> np.ndarray:
        r"""Where site ``k``, now at ``xy``, is held from this frame on.

        Two held points of one rigid body fix its horizontal extent: a site latched
        while still :math:`h` above the floor at distance :math:`L` from an already held
        site of its body would keep its foot tilted by
        :math:`\arcsin(h/L)` for the whole contact, its height pull fighting the
        hold.  So a site
        whose body already has a held site :math:`j` is held at that site's anchor
        plus the flat rest-pose distance, in the current direction:
        :math:`a_k = a_j + d^{rest}_{jk}\, \widehat{(x_k - a_j)}`, consistent with
        the foot standing flat; the first site of a body is held where it is.
        Of several held sites the farthest in the rest pose is used (the
        direction, the foot's heading, is then the most precise).
        """
        if self.rest_distances is None:
            return xy
        d = np.where(self.locked & ~self.on_corner, self.rest_distances[k], np.nan)
        if not np.any(np.isfinite(d)):
            return xy
        j = int(np.nanargmax(d))
        u = xy - self.anchor[j, :2]
        n = float(np.linalg.norm(u))
        return xy if n < 1e-9 else self.anchor[j, :2] + d[j] * u / n

    def _follow_contact(self, k: int, data: mujoco.MjData) -> None:
        r"""Hold a foot pivoting on site ``k`` where it actually rests.

        A rigid foot rolling over its front edge is held at its pivot site, on that edge;
        a foot on its toes alone, at its toe tip's site (``PlanHints.rolling``).
        Where it cannot keep the edge level (an ankle roll at its limit, with the foot
        turned from the leg's plane) it tips onto one corner: the site rises off the floor
        and the foot, turning about the held site, drags the corner it stands on (the
        bundled robot's toe-offs on the PyMO walk, 1-3 mm a frame).  So once the site
        stands more than :data:`TIP_HEIGHT` higher over the foot's lowest point than in the
        rest pose (:attr:`rest_gaps`), with that point on the floor, the hold is on the
        foot's resting patch, the centroid of its material points within :data:`PATCH_TIE`
        of the lowest (a corner; the edge itself where the site sits behind the edge of a
        steeply pitched foot): fixed on the foot, held where it is when taken, taken again
        where the patch moves more than :data:`PATCH_MOVE` on the foot.  Back on the site,
        held where it is, once the site is down at its height again or the foot is off the
        floor (its lowest point more than :data:`TIP_HEIGHT` up: still landing).  A toe
        segment tips the same way: a foot rolled on its toes (an inverted foot in a turn)
        rests on one end of the toe tip's capsule, 3 cm to the side of the site, and held at
        the site the foot turned about it and swept that end over the floor (the CMU dance's
        humanoid: foot slip 1.01 -> 0.42 cm/s).
        ``data``: the previous frame's solution.

        Measured on the bundled robot, holding the patch wherever it lies off the site
        (a flat foot's centre too) made its worst segment on the Bandai punch 6.9 -> 7.9
        degrees and the dance's foot slip 0.31 -> 0.50 cm/s; holding it only where it lies
        to the side of the site left the PyMO walk's foot slip at 0.57 cm/s (0.21).
        """
        gap = float(self.rest_gaps[k]) if self.rest_gaps is not None else np.nan
        task = self.corner[k]
        points = _material_points(self.model, data, {task.body})
        if not np.isfinite(gap) or not len(points):
            return
        low = points[:, 2] - points[:, 3]
        lowest = float(low.min())
        site = data.site_xpos[self.xy[k].site_id]
        if lowest > self.floor + TIP_HEIGHT or site[2] - lowest <= gap + TIP_HEIGHT:
            if self.on_corner[k]:
                self.anchor[k, :2] = site[:2]
                self.on_corner[k] = False
            return
        patch = points[low <= lowest + PATCH_TIE, :3].mean(axis=0)
        patch[2] = lowest
        R = data.xmat[task.body].reshape(3, 3)
        local = R.T @ (patch - data.xpos[task.body])
        if not self.on_corner[k] or np.linalg.norm(local - task.local) > PATCH_MOVE:
            task.local = local
            self.anchor[k, :2] = patch[:2]
            self.on_corner[k] = True

    def turn(self, foot: int, angle: float, heights: np.ndarray | None = None,
             labelled: np.ndarray | None = None) -> np.ndarray | None:
        r"""Turn the holds of ``foot`` by ``angle`` radians about the vertical axis.

        Two held points of one foot fix its heading, so a foot the plan turns
        while it is planted (an actor pivoting on a flat foot) would stay where it
        landed and swing round in one frame when a point is let go.  Its holds are
        turned with the plan instead, about the foot's most distal held point resting on the
        floor (:meth:`_pivot_site`: a flat foot pivots on its toes, one rocked back on its heel
        on the heel), :math:`a_k \leftarrow p + R_z(\alpha)(a_k - p)`.
        Nothing happens with fewer than two points held (one point does not fix the heading).
        The turned points other than the pivot are held softly on this frame (``cost_xy``):
        a hard hold turned where the leg cannot follow at once (a hip rotation at its
        limit) would make the constraints infeasible.  Returns the pivot's horizontal
        position (metres), None if nothing turned.
        """
        held = np.flatnonzero(self.locked & (self.feet == foot))
        if held.size < 2 or angle == 0.0:
            return None
        k = self._pivot_site(held, heights, labelled)
        self.turning[held[held != k]] = True
        pivot = self.anchor[k, :2].copy()
        self.anchor[held, :2] = _turn_about(self.anchor[held, :2], pivot, angle)
        return pivot

    def heights(self, data: mujoco.MjData) -> np.ndarray:
        """``(n,)`` metres: every contact site's height over the floor in ``data``."""
        return data.site_xpos[self._site_ids, 2] - self.floor

    def _pivot_site(self, held: np.ndarray, heights: np.ndarray | None, labelled: np.ndarray | None) -> int:
        """The held site a foot turns about: of its held sites labelled in contact (``labelled``,
        every site's label this frame; all held sites if none is), the most distal of those
        resting on the floor (``heights``: every site's height over the floor now, metres; within
        :data:`RESTING_HEIGHT` of the lowest of them).  A foot rocked back on its heel, its ball
        still held (the hold outlasts its label until the ball lifts clear), turns about its
        heel rather than swinging the heel across the floor.  Without heights: the most distal
        held site."""
        if labelled is not None and labelled[held].any():
            held = held[labelled[held]]
        if heights is None:
            return int(held[-1])
        z = heights[held]
        return int(held[np.flatnonzero(z <= z.min() + RESTING_HEIGHT)[-1]])

    def _release_share(self, k: int, z: float, vz: np.ndarray, start: float, hints: "PlanHints | None") -> float:
        r"""The share of ``cost_xy`` that holds site ``k`` on this frame, 1 (hard) -> 0: for a site
        held next to a held point of another segment (a ball next to a held toe tip), whose two
        holds fix the toes' bend.

        While the foot's toe targets bend up (``hints.bending``) and the site rises (``vz``,
        metres this frame) above ``start`` (metres over the floor ``z``), the hold lets go softly,
        :math:`1 - \operatorname{smoothstep}((z - start) / \text{release\_margin})`, instead of at
        once at the top of the margin (where the toes caught up at their velocity cap: the CMU
        walk's right toe, three frames).  Only rising: a foot landing on its toes keeps its
        holds; only bending: a foot lifting with its toes flexing down let them kink up against
        the actor's (the Bandai punch).  The share never grows again within the contact (a hold
        taken hard again as the bending toes lowered the ball 5 mm locked them again, and they
        snapped at the next release) until the site is back on the floor
        (:data:`RESTING_HEIGHT`) or its own body comes back down (a foot rocking back onto its
        heel is held).
        """
        opt = self.options
        mates = self._rest_partners is not None and bool(np.any(vz[self._rest_partners[k]] < 0.0))
        share = 1.0 if z <= RESTING_HEIGHT or mates else float(self.fade[k])
        bending = hints is not None and hints.bending is not None and bool(hints.bending[k])
        if self.locked[k] and z > start and vz[k] > 0.0 and bending and opt.release_margin > 0:
            share = min(share, 1.0 - smoothstep((z - start) / opt.release_margin))
        return share

    def reset(self) -> None:
        self.locked[:] = False
        self.fade[:] = 1.0
        self.on_corner[:] = False
        self.labelled[:] = False
        self.landed[:] = False
        self.landing[:] = self.clearance_frames + 1
        self._prev_z = None
        self.age[:] = 0

    def update(
        self,
        in_contact: Mapping[str, bool] | np.ndarray,
        data: mujoco.MjData,
        hints: "PlanHints | None" = None,
    ) -> tuple[list[SitePositionTask], list[SitePositionTask | BodyPointTask], np.ndarray]:
        """Advance one frame.

        A site is *engaged* (held horizontally by a hard equality) from the
        frame a labelled site is, or is about to be (one frame ahead at twice
        its current vertical speed, to catch a foot slapping down), within
        ``engage_height`` of the floor; with ``lock_low`` it stays engaged after
        its label ends until it has lifted above the band (plus
        ``release_margin``), so a foot rises before it moves, as a planted foot
        does.  Labelled sites are pulled down onto the floor by a soft height
        task.  A swing foot that skims the floor without a label is not held.
        Offline (``hints`` given), a rigid foot or a toe segment tipped onto a corner is
        held on that corner (:meth:`_follow_contact`), and a site ``hints.soft`` marks is
        held softly.

        Args:
            in_contact: Per site, whether it is labelled in contact on this frame
                (a mapping by site name, or a bool array in ``self.sites`` order).
            data: MuJoCo data holding the previous frame's solution (anchors
                and heights are taken from it).
            hints: Offline, what the planned targets say about each site this
                frame (:class:`PlanHints`); None when streaming.

        Returns:
            ``(soft tasks, equality constraints, engaged flags)``.
        """
        opt = self.options
        if isinstance(in_contact, Mapping):
            flags = np.array([bool(in_contact.get(s, False)) for s in self.sites])
        else:
            flags = np.asarray(in_contact, dtype=bool)
        n = len(self.sites)
        engaged = np.zeros(n, dtype=bool)
        soft: list[SitePositionTask] = []
        hard: list[SitePositionTask | BodyPointTask] = []
        if not opt.plant:
            return soft, hard, engaged
        z = self.heights(data)
        vz = np.zeros(n) if self._prev_z is None else z - self._prev_z
        self._prev_z = z
        for k, task in enumerate(self.tasks):
            sid = task.site_id
            # hysteresis: a held site stays held until it is clearly above the band
            band = opt.engage_height + (opt.release_margin if self.locked[k] else 0.0)
            rolling = hints is not None and bool(hints.rolling[k])
            pivoting = hints is not None and hints.pivoting is not None and bool(hints.pivoting[k])
            low = min(z[k], z[k] + 2.0 * vz[k]) < band or ((rolling or pivoting) and self.locked[k])
            partner = self.locked & self._others[k]
            fade = 1.0  # share of a hold's cost while it lets go (1: hard)
            if partner.any() and not rolling and not pivoting:  # a foot already held: its further holds, without look-ahead
                rigid = self._rest_partners is not None and bool((partner & self._rest_partners[k]).any())
                start = opt.engage_height if rigid else min(opt.settle_height, opt.engage_height)
                low = z[k] < start + (opt.release_margin if self.locked[k] else 0.0)
                if not rigid:
                    fade = self._release_share(k, float(z[k]), vz, start, hints)
            # A lock starts when a labelled site touches down (a labelled site still in
            # the air is pulled down first: holding it in the air would keep it from
            # reaching the floor).  With lock_low it lasts, label or not, until the
            # site lifts clear of the band, so a foot rises before it moves.
            lock_low = opt.lock_low and (hints is None or hints.released is None or not hints.released[k])
            engaged[k] = low and (flags[k] or (lock_low and self.locked[k])) and (hints is None or bool(hints.holdable[k]))
            if engaged[k]:
                if not self.locked[k]:
                    self.anchor[k, :2] = self._anchor_for(k, data.site_xpos[sid, :2])
                    self.anchor[k, 2] = self.floor
                    self.locked[k] = True
                    self.on_corner[k] = False
                if pivoting or rolling:
                    self._follow_contact(k, data)
                hold = self.corner[k] if self.on_corner[k] else self.xy[k]
                hold.set_target(self.anchor[k])
                self.fade[k] = fade
                if hold is self.xy[k]:  # a corner hold (a rigid foot's pivot) never fades
                    hold.set_cost(opt.cost_xy * fade)
                # a foot turning about another held point: this one held softly (FootPlanter.turn)
                gentle = hints is not None and hints.soft is not None and bool(hints.soft[k])
                (soft if self.turning[k] or fade < 1.0 or gentle else hard).append(hold)
            else:
                self.locked[k] = False
                self.on_corner[k] = False
                if not flags[k]:  # the contact is over: its next hold starts hard
                    self.fade[k] = 1.0
            self.free[k] = not flags[k] and not engaged[k]
            self.landed[k] |= not self.free[k]
            lifting = hints is not None and hints.lifting is not None and bool(hints.lifting[k])
            if flags[k] and not rolling and not lifting:
                # pulled onto the floor, the pull ramping in over onset_time
                self.age[k] = self.age[k] + 1 if self.labelled[k] else 0
                ramp = smoothstep((self.age[k] + 1) / self.onset_frames)
                task.set_cost(opt.cost_z * ramp)
                # descend at most max_descent_speed: a foot labelled down while still in
                # the air lands over a few frames instead of slamming down in one
                z_goal = max(self.floor, self.floor + z[k] - opt.max_descent_speed / self.fps)
                task.set_target(np.array([0.0, 0.0, z_goal]))
                soft.append(task)
            self.labelled[k] = flags[k]
        for f, mine in self._foot_sites:
            if self.free[mine].all():  # the foot swings: its sites land afresh
                self.landed[mine] = False
                self.landing[f] = 0
            else:
                self.landing[f] += 1
        self.turning[:] = False
        return soft, hard, engaged

    def clearance_share(self, foot: int) -> float:
        r"""How much of its swing clearance ``foot`` keeps on this frame, 1 -> 0: all of it
        while the foot swings, then :math:`1 - \operatorname{smoothstep}(n / (N + 1))` on
        the :math:`n`-th frame since one of its sites was labelled or held, :math:`N` the
        whole frames within ``onset_time`` (:attr:`clearance_frames`; with the default ``onset_time``: 3 at 120 fps, none at
        30 fps): the clearance eases out as the height pull eases in, a handover rather than
        a switch.

        (A rigid foot's geoms held 12 mm up to the end of its swing while its targets came
        down to the floor dropped in two frames at heel strike, and its ankle roll and knee
        reversed at up to 1000 deg/s: the Unitree G1 on the PyMO walk.)
        """
        n = int(self.landing[foot])
        return 1.0 - smoothstep(n / (self.clearance_frames + 1)) if n else 1.0


class FootAnchor:
    r"""Causal horizontal offset that holds one foot's *targets* still during contact.

    The actor's own feet slide during stance (raw capture slides, and so do
    targets built for other proportions), so locking the character's foot
    while its target drifts would store up a gap that snaps back on release.
    Instead the foot's targets are shifted by an offset :math:`o(t)`
    (horizontal, metres):

    * when a contact begins and the foot has no other contact, the anchor is
      where the *character's* point is (previous frame's solution), so the
      targets agree with the planted contact sites;
    * while the heel is in contact, :math:`o = A_h - T_{ankle}(t)`; while only
      the toe is, :math:`o = A_t - T_{toe}(t)` (a toe anchor set during heel
      contact follows the heel's offset, so switching is continuous);
    * after release, :math:`o` fades to zero along a smoothstep over
      ``release_time``, so the foot rejoins the actor's motion during the
      swing without a pop.  It fades from where the character's ankle is
      (previous frame's solution against that frame's target), not from the
      anchor's offset: a foot held on its toes, its ankle short of a target its
      shape cannot reach, jumped that gap in one frame when it let go (fewer pops on
      the streamed jumps, dance and Bandai walk; README, Streaming).
    * a foot whose holds turn (:meth:`FootPlanter.turn`) turns its anchors with
      them (:meth:`turn`).
    """

    def __init__(self, fps: float, release_time: float = 0.25) -> None:
        self.release_frames = max(1, int(round(release_time * fps)))
        self.offset = np.zeros(2)
        self.heel_anchor: np.ndarray | None = None
        self.toe_anchor: np.ndarray | None = None
        self._fade_from = np.zeros(2)
        self._fade_left = 0
        self._was_held = False
        self._last_ankle: np.ndarray | None = None  # the previous frame's (unshifted) ankle target

    @property
    def held(self) -> bool:
        return self.heel_anchor is not None or self.toe_anchor is not None

    def step(
        self,
        heel: bool,
        toe: bool,
        ankle_xy: np.ndarray,
        toe_xy: np.ndarray,
        ankle_now: np.ndarray | None = None,
        toe_now: np.ndarray | None = None,
        base: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance one frame; returns the offset to add to this foot's targets.

        Args:
            heel, toe: Contact labels of this frame.
            ankle_xy, toe_xy: This frame's (unshifted) ankle and toe targets.
            ankle_now, toe_now: The character's ankle and toe positions in the
                previous frame's solution (None: use the shifted targets).
            base: The offset a free foot returns to (the root offset; default 0).
        """
        base = np.zeros(2) if base is None else np.asarray(base, dtype=float)
        last, self._last_ankle = self._last_ankle, np.array(ankle_xy, dtype=float)
        free = self.heel_anchor is None and self.toe_anchor is None
        if heel and self.heel_anchor is None:
            self.heel_anchor = (ankle_now if free and ankle_now is not None else ankle_xy + self.offset).copy()
        if toe and self.toe_anchor is None:
            self.toe_anchor = (toe_now if free and toe_now is not None else toe_xy + self.offset).copy()
        if not heel:
            self.heel_anchor = None
        if not toe:
            self.toe_anchor = None
        if self.heel_anchor is not None:
            new = self.heel_anchor - ankle_xy
            if self.toe_anchor is not None:  # keep the toe anchor consistent with the heel's
                self.toe_anchor = toe_xy + new
        elif self.toe_anchor is not None:
            new = self.toe_anchor - toe_xy
        else:
            if self._fade_left == 0 and self._was_held:
                # hand back relative to the base, from where the character's ankle is
                start = self.offset if ankle_now is None or last is None else ankle_now - last
                self._fade_from = start - base
                self._fade_left = self.release_frames
            if self._fade_left > 0:
                self._fade_left -= 1
                new = base + self._fade_from * smoothstep(self._fade_left / self.release_frames)
            else:
                new = base.copy()
            self._was_held = False
            self.offset = new
            return new
        self._fade_left = 0
        self._was_held = True
        self.offset = new
        return new

    def turn(self, pivot: np.ndarray, angle: float) -> None:
        r"""Turn the anchors by ``angle`` radians about the vertical through ``pivot`` (metres,
        horizontal), :math:`A \leftarrow p + R_z(\alpha)(A - p)`: the foot's holds have turned
        (:meth:`FootPlanter.turn`), and its targets turn with them.  Left where they were,
        the ankle's target stayed where the foot landed while the foot turned about its toes
        and the ankle with it: the streamed jumps' robot turned a planted foot 58 degrees
        onto the actor's heading over a second, its ankle ended 12 cm from its target, and
        the foot jumped 10 cm in one frame when it let go."""
        if self.heel_anchor is not None:
            self.heel_anchor = _turn_about(self.heel_anchor, pivot, angle)
        if self.toe_anchor is not None:
            self.toe_anchor = _turn_about(self.toe_anchor, pivot, angle)


def _turn_about(points: np.ndarray, pivot: np.ndarray, angle: float) -> np.ndarray:
    r"""Horizontal points ``(..., 2)`` (metres) turned by ``angle`` radians about the vertical
    through ``pivot`` ``(2,)``: :math:`p + R_z(\alpha)(a - p)` (a new array)."""
    c, s = np.cos(angle), np.sin(angle)
    d = np.asarray(points, dtype=float) - pivot
    out = np.empty_like(d)
    out[..., 0] = pivot[0] + c * d[..., 0] - s * d[..., 1]
    out[..., 1] = pivot[1] + s * d[..., 0] + c * d[..., 1]
    return out


@dataclass
class _ReleaseWatch:
    """What a stream's causal release of one foot point reads of its target during a contact
    (:meth:`Planting._heels_moving`, :meth:`Planting._toes_moving`): the target's position on
    the last frame it was tracked, its lowest height (metres) over the part of the contact its
    rule reads, whether its label was on last frame, and whether its hold has been let go early."""

    last: np.ndarray | None = None
    low: float = math.inf
    labelled: bool = False
    gone: bool = False

    def step(self, position: np.ndarray | None) -> np.ndarray | None:
        """``position - last`` (metres, ``(3,)``; None on the first tracked frame), and
        ``position`` kept as the last; None for ``position`` (the target lost: its stand-in
        position is no motion) forgets the last."""
        last, self.last = self.last, None if position is None else np.array(position, dtype=float)
        return None if last is None or position is None else self.last - last


def _toward_zero(offset: np.ndarray, by: float) -> np.ndarray:
    """``offset`` shortened by ``by`` metres (to none at most)."""
    n = float(np.linalg.norm(offset))
    return offset * max(0.0, 1.0 - by / n) if n > by else np.zeros_like(offset)


def _material_points(model: mujoco.MjModel, data: mujoco.MjData, bodies: set[int]) -> np.ndarray:
    """``(K, 4)`` world lowest-point candidates ``(x, y, z, radius)`` of the collision geoms
    of ``bodies`` in the pose of ``data`` (:func:`~physmocap.models.geometry.geom_candidates`)."""
    rows = []
    for g in character_geoms(model, collision_only=True):
        if int(model.geom_bodyid[g]) in bodies:
            c = geom_candidates(model, g)
            xyz = data.geom_xpos[g] + c[:, :3] @ data.geom_xmat[g].reshape(3, 3).T
            rows.append(np.hstack([xyz, c[:, 3:]]))
    return np.vstack(rows) if rows else np.zeros((0, 4))


class Planting:
    """Per-frame planting for one character: foot target offsets plus contact-site locks.

    Causal: each :meth:`step` uses only this frame's labels and targets and the
    previous frame's solution, so offline and streaming retargeting share it.
    Offline retargeting plans the feet over the whole clip first
    (:func:`~physmocap.ik.footplan.planted_positions`) and passes
    ``anchored=False``: the site locks then hold where the planned targets are.

    Args:
        character: The :class:`~physmocap.models.Character`.
        names: Canonical joints of the targets, in target order.
        fps: Frame rate.
        options: :class:`PlantOptions`.
        floor: Floor height (metres).
    """

    def __init__(
        self,
        character,
        names,
        fps: float,
        options: PlantOptions | None = None,
        floor: float = 0.0,
        anchored: bool = True,
        has_orientation: Sequence[bool] | None = None,
    ) -> None:
        self.options = opt = options or PlantOptions()
        #: False when the targets were planted offline (:mod:`.footplan`): only the site
        #: locks, height pulls and swing clearances act, the targets are used as given.
        self.anchored = bool(anchored)
        self.character = character
        self.names = tuple(names)
        #: side -> the target columns of its ankle, toe and toe end (the toes' bend, PlanHints.bending)
        self._bend_columns = {side: tuple(self.names.index(f"{side}_{j}") for j in ("ankle", "toe", "toe_end"))
                              for side in ("left", "right")
                              if all(f"{side}_{j}" in self.names for j in ("ankle", "toe", "toe_end"))}
        self._last_bend: dict[str, float] = {}
        model = character.model
        self.sites = [s for side in ("left", "right") for s in character.contacts.get(side, ())]
        self.site_label = {}
        for side in ("left", "right"):
            for k, site in enumerate(character.contacts.get(side, ())):
                self.site_label[site] = f"{side}_heel" if k == 0 else f"{side}_toe"
        # Offline the labels are final and the targets planned (.footplan): a site is held
        # exactly while labelled (no hold-until-lifted hysteresis).
        lock_opt = opt if self.anchored else dataclasses.replace(opt, lock_low=False)
        feet = [0 if s in character.contacts.get("left", ()) else 1 for s in self.sites]
        self.locks = FootPlanter(
            model, self.sites, fps, lock_opt, floor=floor, rest_distances=self._rest_distances(character), feet=feet,
            rest_gaps=self._rest_gaps(character),
        )
        #: per site, its role while only the toes are down (offline; :meth:`_toe_roles`)
        feet_bodies = foot_bodies(model, character.contacts)
        self._foot_bodies = {side: feet_bodies.get(side, []) for side in ("left", "right")}
        roles = {k: v for side in ("left", "right") for k, v in self._toe_roles(model, character, side).items()}
        self._release = np.array([roles.get(site) == "release" for site in self.sites], dtype=bool)
        #: streaming: per side, whether its heel has been labelled since its toes came down
        #: (a foot down on its toes alone after that rolls over them; one landing toes first
        #: does not)
        self._heel_down = {"left": False, "right": False}
        #: offline: per side, frames since its heel's label started (0: not labelled), and the
        #: frames of LANDING_HOLD_TIME (at least one)
        self._heel_age = {"left": 0, "right": 0}
        self._landing_frames = max(1, int(round(LANDING_HOLD_TIME * fps)))
        self._pivot = np.array([roles.get(site) == "pivot" for site in self.sites], dtype=bool)
        #: the side (left, right) of each site
        self._site_side = ["left" if s in character.contacts.get("left", ()) else "right" for s in self.sites]
        self._side_sites = {side: [k for k, v in enumerate(self._site_side) if v == side] for side in ("left", "right")}
        #: per side, a rigid foot (its toe sites on the heel's body, role "pivot"): its geoms'
        #: swing clearance eases out as it lands (:meth:`clearance_bodies`).  Measured without
        #: the restriction, a foot with a toe joint met its toe joint's velocity cap instead
        #: (CMU walk humanoid: right toe extension at its cap on 3 -> 6 frames).
        self._rigid = {side: bool(any(self._pivot[k] for k in ks)) for side, ks in self._side_sites.items()}
        held = np.array([roles.get(site) == "hold" for site in self.sites], dtype=bool)
        has_release = {side: any(self._release[k] for k in ks) for side, ks in self._side_sites.items()}
        #: sites on a toe segment of a foot that also has sites on its own body
        self._toe_segment = held & np.array([has_release[side] for side in self._site_side], dtype=bool)
        #: sites on the heel's body of a foot with a toe segment, other than its ball: the
        #: points that lift as the foot rolls over its toes
        self._heel_sites = ~held & ~self._release & np.array([has_release[side] for side in self._site_side], dtype=bool)
        rolling = set(self.toe_contacts())
        #: toe-segment sites whose height the offline plan sets while only the toes are down
        self._rolling = held & np.array([side in rolling for side in self._site_side], dtype=bool)
        self.lengths: dict[str, tuple[int, int, int, float, float]] = {}
        rest = {c: character.rest_positions()[c] for c in self.names if c in character.rest_positions()}
        for side in ("left", "right"):
            hip, knee, ankle = f"{side}_hip", f"{side}_knee", f"{side}_ankle"
            if all(j in rest for j in (hip, knee, ankle)):
                self.lengths[side] = (
                    self.names.index(hip),
                    self.names.index(knee),
                    self.names.index(ankle),
                    float(np.linalg.norm(rest[knee] - rest[hip])),
                    float(np.linalg.norm(rest[ankle] - rest[knee])),
                )
        self.anchors = {side: FootAnchor(fps, opt.anchor_release_time) for side in ("left", "right")}
        #: horizontal offset of the whole body from the actor's (scaled) path, metres
        self.root_offset = np.zeros(2)
        #: per side, the causal releases of its toe (:meth:`_toes_moving`) and heel (:meth:`_heels_moving`)
        self._toe_watch = {side: _ReleaseWatch() for side in ("left", "right")}
        self._heel_watch = {side: _ReleaseWatch() for side in ("left", "right")}
        #: the sites labelled by a heel (every foot's, rigid or not)
        self._heel_labelled_sites = np.array([self.site_label[site].endswith("_heel") for site in self.sites], dtype=bool)
        self._root_alpha = 1.0 - np.exp(-1.0 / (max(opt.root_follow_time, 1e-6) * fps)) if opt.root_follow_time > 0 else 0.0
        foot_joints = {f"{side}_{j}" for side in ("left", "right") for j in FOOT_JOINTS}
        foot_joints |= {f"{side}_knee" for side in ("left", "right")}
        self._body = np.array([i for i, n in enumerate(self.names) if n not in foot_joints], dtype=int)
        self.feet = {}
        for side in ("left", "right"):
            ankle = f"{side}_ankle"
            if ankle not in self.names:
                continue
            toe = next((f"{side}_{p}" for p in ("toe", "toe_end") if f"{side}_{p}" in self.names), ankle)
            ref = {}
            for j in (ankle, toe):
                tf = character.tracked[j]
                ref[j] = (tf.kind, tf.object_id(model))
            moved = [self.names.index(f"{side}_{j}") for j in FOOT_JOINTS if f"{side}_{j}" in self.names]
            self.feet[side] = (self.names.index(ankle), self.names.index(toe), ref[ankle], ref[toe], moved)
        self._has_orientation = (np.zeros(len(self.names), dtype=bool) if has_orientation is None
                                 else np.asarray(has_orientation, dtype=bool))
        #: turns a foot held at two points towards its target heading (:mod:`.footturn`)
        self._turner = self._heading_follower(character)

    def _rest_distances(self, character) -> np.ndarray:
        """``(n, n)`` horizontal rest-pose distances between contact sites on the same body
        (NaN between bodies and on the diagonal), for :meth:`FootPlanter._anchor_for`:
        only a rigid pair keeps its rest distance when both of its sites are down (toes
        may be bent)."""
        model = character.model
        data = character.rest_data()
        xy = np.array([data.site(s).xpos[:2] for s in self.sites]).reshape(-1, 2)
        body = np.array([int(model.site(s).bodyid[0]) for s in self.sites])
        d = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
        d[body[:, None] != body[None]] = np.nan
        np.fill_diagonal(d, np.nan)
        return d

    def _rest_gaps(self, character) -> np.ndarray:
        """``(n,)`` each contact site's height (metres) over the lowest material point of its
        body's collision geoms in the rest pose (NaN for a body without any), for
        :meth:`FootPlanter._follow_contact`."""
        model = character.model
        data = character.rest_data()
        gaps = np.full(len(self.sites), np.nan)
        for k, s in enumerate(self.sites):
            points = _material_points(model, data, {int(model.site(s).bodyid[0])})
            if len(points):
                gaps[k] = data.site(s).xpos[2] - float((points[:, 2] - points[:, 3]).min())
        return gaps

    @staticmethod
    def _toe_roles(model: mujoco.MjModel, character, side: str) -> dict[str, str]:
        """How each toe-group contact site acts while only the toes are down (offline).

        ``"hold"``: on a toe segment (a body below the heel's, moved by a joint): held and pulled down,
        the toes stay flat.  ``"release"``: on the heel's body of a foot that has a toe
        segment: the foot rolls over its toes and the site lifts.  ``"pivot"``: on the
        heel's body of a rigid foot: held horizontally and pulled down only softly
        (``pivot_cost``), so the foot
        rolls over its front edge.
        """
        sites = list(character.contacts.get(side, ()))
        if len(sites) < 2:
            return {}

        heel = int(model.site(sites[0]).bodyid[0])

        def on_toes(name: str) -> bool:
            """The site's body is below the heel's, with a joint between (a body welded
            to the foot, such as a robot's toe link without a joint, is the foot)."""
            b, jointed = int(model.site(name).bodyid[0]), False
            while b > 0 and b != heel:
                jointed |= bool(model.body_jntnum[b] > 0)
                b = int(model.body_parentid[b])
            return b == heel and jointed

        toes = {s: on_toes(s) for s in sites[1:]}
        has_toes = any(toes.values())
        return {s: "hold" if toes[s] else ("release" if has_toes else "pivot") for s in sites[1:]}

    def stance_heights(self) -> dict[str, float]:
        """Canonical ankle/toe joint -> its height above the floor in the character's rest pose."""
        rest = self.character.rest_positions()
        return {c: float(rest[c][2] - self.locks.floor) for c in self.names if c in rest}

    def toe_contacts(self) -> dict[str, ToeContact]:
        """Side -> the :class:`~physmocap.ik.footplan.ToeContact` of a foot whose toe segment
        (``toe`` and ``toe_end`` tracked) carries contact sites (role ``"hold"``)."""
        model = self.character.model
        rest = self.character.rest_positions()
        data = self.character.rest_data()
        out: dict[str, ToeContact] = {}
        for side in ("left", "right"):
            toe, tip = f"{side}_toe", f"{side}_toe_end"
            held = [s for s, role in self._toe_roles(model, self.character, side).items() if role == "hold"]
            if not held or toe not in rest or tip not in rest or toe not in self.names or tip not in self.names:
                continue
            points = _material_points(model, data, {int(model.site(s).bodyid[0]) for s in held})
            if not len(points):  # no collision geometry on the toes: their contact sites
                points = np.array([[*data.site(s).xpos, 0.0] for s in held])
            out[side] = ToeContact(
                direction=rest[tip] - rest[toe],
                offsets=points[:, :3] - rest[toe],
                radii=points[:, 3],
                height=float((points[:, 2] - points[:, 3]).min() - self.locks.floor),
            )
        return out

    def rigid_feet(self) -> dict[str, RigidFoot]:
        """Side -> the :class:`~physmocap.ik.footplan.RigidFoot` of a foot without toe joints
        (its toe sites on the heel's body, role ``"pivot"``) whose ankle is tracked."""
        model = self.character.model
        data = self.character.rest_data()
        rest_frames = character_rest_frames(self.character)
        out: dict[str, RigidFoot] = {}
        for side in ("left", "right"):
            ankle = f"{side}_ankle"
            front = [s for s, role in self._toe_roles(model, self.character, side).items() if role == "pivot"]
            if not front or ankle not in self.names:
                continue
            pos, quat = rest_frames[ankle]
            points = _material_points(model, data, set(self._foot_bodies[side]))
            if not len(points):  # no collision geometry: the contact sites
                points = np.array([[*data.site(s).xpos, 0.0] for s in self.character.contacts[side]])
            out[side] = RigidFoot(
                rest_quat=quat,
                front=np.mean([data.site(s).xpos for s in front], axis=0) - pos,
                offsets=points[:, :3] - pos,
                radii=points[:, 3],
                height=float((points[:, 2] - points[:, 3]).min() - self.locks.floor),
            )
        return out

    def _heels_moving(self, positions: np.ndarray, labels: Mapping[str, bool],
                      valid: np.ndarray | None = None) -> Mapping[str, bool]:
        """``labels`` with the heel of a causally anchored foot let go once its ankle target
        lifts (rises more than ``release_margin`` above its lowest since the heel's label
        began) and moves horizontally faster than ``PlantOptions.heel_release_speed``
        (between two frames on which it is tracked: ``valid``): under its label, and after
        it while its sites stay held because they have not lifted (``lock_low``); let go
        until the label begins again.  A rigid heel held low cannot lift, and its hold kept
        the foot where it landed while the actor's ankle rolled on over the toes: the
        streamed PyMO walk's robot stored up 10-12 cm at every push-off, which the body
        followed (its pelvis 6.7 cm from the actor's scaled path on average).  A heel whose
        target slides without lifting (a shuffle, a spin) stays held.  The heel's sites are
        then released (:meth:`_stream_hints`); the toes hold the foot alone, and
        :meth:`_toes_moving` lets them go in turn.  A heel whose ankle target has risen past
        the band a free site lets go above (``engage_height + release_margin``) lets go
        however slowly it moves: a heel raised in place (the end of the CMU walk), held low
        while its target rose 3 cm, jumped up with the toes' release."""
        out = dict(labels)
        if self.options.heel_release_speed <= 0:
            return out
        limit = self.options.heel_release_speed / self.locks.fps
        for side, foot in self.feet.items():
            key = f"{side}_heel"
            labelled = bool(labels.get(key, False))
            watch = self._heel_watch[side]
            if valid is not None and not bool(valid[foot[0]]):
                watch.step(None)
                continue
            ankle = np.asarray(positions[foot[0]], dtype=float)
            if labelled and not watch.labelled:  # a new contact
                watch.gone, watch.low = False, float(ankle[2])
            watch.labelled = labelled
            if labelled or not watch.gone:
                watch.low = min(watch.low, float(ankle[2]))
            moved = watch.step(ankle)
            rise = float(ankle[2]) - watch.low
            if rise > self.options.release_margin and moved is not None and float(np.linalg.norm(moved[:2])) > limit:
                watch.gone = True
            # risen past the band a free site lets go above: the actor's heel is off the floor
            # however slowly it moves (a heel raised in place)
            if rise > self.options.engage_height + self.options.release_margin:
                watch.gone = True
            if watch.gone:
                out[key] = False
        return out

    def _toes_moving(self, positions: np.ndarray, labels: Mapping[str, bool],
                     valid: np.ndarray | None = None) -> Mapping[str, bool]:
        """``labels`` with the toe of a causally anchored foot let go once its toe target moves
        faster than ``PlantOptions.toe_release_speed`` (horizontally, between two frames on
        which it is tracked: ``valid``) while only the toes are labelled: a causal label ends
        some 50-70 ms after the foot has left the floor
        (:class:`~physmocap.ik.contacts.ContactStream`), and a toe held that long behind a
        foot already swinging stores up a 20-35 cm offset that the body follows.  Let go
        until the toe's label ends; after it, a toe still held because it has not lifted
        (``lock_low``) lets go the same way (its target racing on, the foot rolled about the
        held tip and fell 34 cm behind: the 30 fps Bandai walk).  Under its label the speed is
        the target's in three dimensions: a foot taking off upwards (a jump) was held by its toe
        for the label's lag while the actor's ankle rose 5-6 cm, then sprang up 6 cm in one
        frame (the streamed CMU jumps' robot, frame 595).  A rigid foot's toe (no toe joint:
        ``_rigid``) also lets go once its target rises more than ``release_margin`` above its
        lowest since the toes alone are labelled, however slowly: the foot cannot bend its toes
        to stay down.  (Its lowest in the whole contact let the toe go the frame the heel's
        label ended wherever the actor's toe joint had risen while rolling onto it: the CMU
        walk's robot and G1 bent their knees 8-18 degrees early at every push-off, the actor's
        leg straight, found on the rendered review.)  A
        foot with toes bends them instead (the CMU actor's toe targets rise 1-2 cm as he rolls
        over them; let go there, the humanoid's knee bent 7 degrees early at every left push-off
        of the CMU walk).  A foot without a toe target is left alone."""
        out = dict(labels)
        limit = self.options.toe_release_speed / self.locks.fps
        for side, foot in self.feet.items():
            if foot[1] == foot[0]:
                continue  # no toe target: the ankle's speed is not the toe's
            watch = self._toe_watch[side]
            if valid is not None and not bool(valid[foot[1]]):
                watch.step(None)
                continue
            toe = np.asarray(positions[foot[1]], dtype=float)
            moved = watch.step(toe)
            key = f"{side}_toe"
            if not labels.get(key, False):
                # the label over: a toe still held because it has not lifted (lock_low) lets go
                # once its target moves off as fast
                watch.gone = moved is not None and float(np.linalg.norm(moved[:2])) > limit
                watch.low = math.inf
                continue
            # its lowest while the toes alone are down: a toe target that rose while the heel was
            # still labelled (an actor rolling onto his toes) is where the toes stand
            watch.low = math.inf if labels.get(f"{side}_heel", False) else min(watch.low, float(toe[2]))
            if not watch.gone and moved is not None and not labels.get(f"{side}_heel", False):
                step = math.hypot(float(np.linalg.norm(moved[:2])), float(moved[2]))
                # a rigid foot cannot bend its toes as its toe target rises: it follows the rise
                rising = self._rigid[side] and moved[2] > 0 and float(toe[2]) > watch.low + self.options.release_margin
                watch.gone = step > limit or bool(rising)
            if watch.gone:
                out[key] = False
        return out

    def leg_lengths(self) -> dict[str, tuple[float, float]]:
        """Side -> (thigh, shank) length of the character (metres)."""
        return {side: (v[3], v[4]) for side, v in self.lengths.items()}

    def clearance_bodies(self) -> dict[int, float]:
        """Body id -> clearance height for the bodies of feet with no contact at all this
        frame (after :meth:`step`): every collision geom of a swing foot clears the floor;
        under a rigid foot that has just landed the clearance eases out
        (:meth:`FootPlanter.clearance_share`)."""
        c = self.options.clearance
        if not self.options.plant or c <= 0:
            return {}
        out: dict[int, float] = {}
        for side in ("left", "right"):
            ks = self._side_sites[side]
            if not ks:
                continue
            if self._rigid[side]:  # eased out as the foot lands (FootPlanter.clearance_share)
                share = self.locks.clearance_share(int(self.locks.feet[ks[0]]))
            else:
                share = 1.0 if all(self.locks.free[k] for k in ks) else 0.0
            if share > 0.0:
                for b in self._foot_bodies[side]:
                    out[b] = c * share
        return out

    def clearance_sites(self) -> dict[int, float]:
        """Site id -> clearance height for this frame's swing sites (after :meth:`step`): free
        sites that have not been down since their foot last swung, of a foot none of whose
        sites is held.  A heel lifting off while its toes are still down is not swinging:
        held up to the clearance at once, it rose 12 mm in one frame at every heel-off (and
        the pelvis with it).  Offline, nor is a rigid foot's front edge coming down after its
        heel (its geoms' clearance already eases out as it lands, :meth:`clearance_bodies`):
        held 12 mm up until its own label began, the foot slapped flat in one frame (the
        bundled robot on the CMU walk: its toe site 10-12 mm down in that frame at every heel
        strike, and the pelvis 4-5 mm with it); the floor still bounds it.  A foot with toes
        keeps the clearance there (without it, a hand of an all-fours fixture hovered
        13-18 mm), and so does a stream (mixed on the streamed walks; docs/history.md, stop 35)."""
        c = self.options.clearance
        if not self.options.plant or c <= 0:
            return {}
        locks = self.locks
        held = {side: not self.anchored and self._rigid[side] and any(not locks.free[k] for k in ks)
                for side, ks in self._side_sites.items()}
        return {t.site_id: c for t, f, down, side in zip(locks.tasks, locks.free, locks.landed, self._site_side)
                if f and not down and not held[side]}

    def _heading_follower(self, character) -> HeadingFollower:
        """The :class:`~.footturn.HeadingFollower` of this character's feet (offline planting)."""
        data = character.rest_data()
        rest = character_rest_frames(character)
        feet = {}
        for side in ("left", "right"):
            ks = np.array(self._side_sites[side], dtype=int)
            if side not in self.feet or ks.size < 2:
                continue
            ia, it = self.feet[side][:2]
            rest_sites = np.array([data.site_xpos[self.locks.tasks[k].site_id] for k in ks])
            if np.hypot(*(rest_sites[-1, :2] - rest_sites[0, :2])) < MIN_HEADING_SPAN:
                continue  # heel and toe sites stacked: two held points give it no heading
            ankle_pos, ankle_rest = rest[self.names[ia]]
            ankle_toe = None if ia == it else rest[self.names[it]][0] - ankle_pos
            feet[side] = (ia, it, ks, rest_sites, ankle_rest, ankle_toe)
        opt = self.options
        legs = {side: spec[:3] for side, spec in self.lengths.items() if side in feet}
        model = character.model
        # side -> its hip's, knee's and ankle's frames as (is a site, id), resolved once
        self._leg_frames = {side: tuple((f.kind == "site", f.object_id(model))
                                        for f in (character.tracked[self.names[i]] for i in legs[side]))
                            for side in legs}
        return HeadingFollower(self._has_orientation, feet, self.locks.fps, opt.pivot_threshold,
                               opt.heading_rate, HEADING_PITCH, legs)

    def _turn_holds(self, positions: np.ndarray, orientations: np.ndarray | None, valid: np.ndarray | None,
                    data: mujoco.MjData, labelled: np.ndarray | None = None) -> None:
        """Turn each foot's holds towards its target heading (:class:`~.footturn.HeadingFollower`,
        :meth:`FootPlanter.turn`)."""
        legs = {side: np.array([data.site_xpos[i] if site else data.xpos[i] for site, i in frames])
                for side, frames in self._leg_frames.items()}
        turns = self._turner.turns(positions, orientations, valid, self.locks.locked, self.locks.anchor, legs)
        heights = self.locks.heights(data)
        for s, side in enumerate(("left", "right")):
            if turns.get(side, 0.0) != 0.0:
                pivot = self.locks.turn(s, turns[side], heights, labelled)
                if pivot is not None and self.anchored:  # the targets' anchors turn with the holds
                    self.anchors[side].turn(pivot, turns[side])

    def _stream_hints(self, positions: np.ndarray, labels: Mapping[str, bool], toe: np.ndarray, heel: np.ndarray,
                      first: bool) -> PlanHints:
        """What a causal foot knows about each site this frame (:class:`PlanHints`; streaming).

        A foot whose heel label has ended while its toes stay down, after its heel was down
        in this contact, rolls over its toes as offline (without the plan's toe heights):
        its heel lets go with its label, its ball is held where it rests but not pulled
        down, and lets go softly while the toe targets bend up.  A foot whose toe has let go
        (:meth:`_toes_moving`) lets go of every site at once.  Measured on the streamed PyMO
        walk (humanoid): the pelvis sank up to 8 cm below its target in late stance and
        rose 5-7 cm in two frames at every toe-off (vertical speed p99 2.89 m/s against the
        actor's 0.61); with these holds 0.74 m/s, no such rise (docs/history.md, stop 32).
        """
        rolled = np.array([self._heel_down[side] for side in self._site_side], dtype=bool)
        for side in ("left", "right"):
            if not labels.get(f"{side}_toe", False):
                self._heel_down[side] = False
            elif labels.get(f"{side}_heel", False):
                self._heel_down[side] = True
        rolling_foot = toe & ~heel & rolled
        bending = self._toes_bending(positions, first)
        bends = np.array([bending.get(side, False) for side in self._site_side], dtype=bool)
        gone = np.array([self._toe_watch[side].gone for side in self._site_side], dtype=bool)
        gone |= np.array([self._heel_watch[side].gone for side in self._site_side], dtype=bool) & self._heel_labelled_sites
        n = len(self.sites)
        return PlanHints(
            rolling=np.zeros(n, dtype=bool),
            holdable=np.ones(n, dtype=bool),
            lifting=rolling_foot & self._release,
            bending=rolling_foot & bends,
            released=(rolling_foot & self._heel_sites) | gone,
        )

    def _toes_bending(self, positions: np.ndarray, first: bool) -> dict[str, bool]:
        """Side -> whether its toe targets bend up on this frame: the pitch of ``toe ->
        toe_end`` above that of ``ankle -> toe`` grows from the previous frame's (False on
        the first frame, and for a foot without the three targets)."""
        if first:
            self._last_bend.clear()
        out = {}
        for side, (a, t, e) in self._bend_columns.items():
            foot, toes = positions[t] - positions[a], positions[e] - positions[t]
            bend = math.atan2(toes[2], math.hypot(toes[0], toes[1])) - math.atan2(foot[2], math.hypot(foot[0], foot[1]))
            last = self._last_bend.get(side)
            out[side] = last is not None and bend > last
            self._last_bend[side] = bend
        return out

    @staticmethod
    def _xy(data: mujoco.MjData, ref: tuple[str, int]) -> np.ndarray:
        kind, i = ref
        return (data.site_xpos[i] if kind == "site" else data.xpos[i])[:2].copy()

    def step(
        self, positions: np.ndarray, labels: Mapping[str, bool], data: mujoco.MjData, first: bool = False,
        valid: np.ndarray | None = None, orientations: np.ndarray | None = None,
    ) -> tuple[np.ndarray, list[SitePositionTask], list[SitePositionTask | BodyPointTask], np.ndarray]:
        """Shifted targets ``(N, 3)``, soft tasks, equality constraints, and the
        foot offsets ``(2, 2)`` (left, right); ``valid`` ``(N,)``: which targets are tracked
        on this frame (None: all); ``orientations`` ``(N, 4)`` x-y-z-w: the targets'
        orientations (offline: a held foot turns towards its ankle's, :mod:`.footturn`)."""
        out = np.array(positions, dtype=float, copy=True)
        offsets = np.zeros((2, 2))
        if not self.options.plant:
            return out, [], [], offsets
        if self.anchored:
            # the toes' release reads the heels' labels, not their early release: a heel let go
            # leaves the foot rolling on its held toes (let go with the heel, the whole foot
            # snapped 2-3 cm onto its targets in one frame at push-off: the CMU walk humanoid)
            labels = self._heels_moving(positions, self._toes_moving(positions, labels, valid), valid)
        flags = np.array([bool(labels.get(self.site_label[site], False)) for site in self.sites])
        toe = np.array([bool(labels.get(f"{side}_toe", False)) for side in self._site_side], dtype=bool)
        heel = np.array([bool(labels.get(f"{side}_heel", False)) for side in self._site_side], dtype=bool)
        toes_only = np.zeros(len(self.sites), dtype=bool) if self.anchored else toe & ~heel
        hints = None
        if self.anchored:
            hints = self._stream_hints(positions, labels, toe, heel, first)
        else:
            # heel up, toes down: the foot rolls over its toes; its ball is held where it rests
            # (not pulled down) until it lifts, so it rolls about its contact instead of sliding
            # round the toe joint above it
            # The toes of a flat foot (heel and toes labelled) are pulled down, never held: its
            # heel and ball already fix it, a tip held where it first touched would lock the
            # toes in their landing bend, and a third held point over a straight leg made the
            # QP throw the body 18 cm sideways for a frame (Bandai walk).  Toes rolling with
            # the actor's (their height planned by the toe segment, .footplan) are held, not pulled.
            for side in self._heel_age:
                self._heel_age[side] = self._heel_age[side] + 1 if labels.get(f"{side}_heel", False) else 0
            heel_held = np.array([bool(np.any(self.locks.locked[self._side_sites[side]] & self._heel_sites[self._side_sites[side]]))
                                  or self._heel_age[side] > self._landing_frames for side in self._site_side], dtype=bool)
            waiting = toe & heel & self._toe_segment
            # The heel labelled but not held yet (at 30 fps it is often labelled a frame before it
            # is down): a held toe tip keeps its hold, softly, until it is, for LANDING_HOLD_TIME
            # at most.  Let go at once, the foot was held nowhere for that frame and slid 1-5 cm
            # towards its plan (the Bandai punch); held hard, a third hold threw the body 36 cm
            # (the same clip).
            landing = waiting & ~heel_held & self.locks.locked
            waiting = waiting & ~landing
            bending = self._toes_bending(positions, first)
            hints = PlanHints(rolling=toes_only & self._rolling, holdable=~waiting, lifting=toes_only & self._release,
                              pivoting=toes_only & self._pivot, soft=landing,
                              bending=np.array([bending.get(side, False) for side in self._site_side], dtype=bool))
        self._turn_holds(positions, orientations, valid, data, flags)  # offline and streaming alike
        tasks, hard, engaged = self.locks.update(flags, data, hints)
        if hints is not None and hints.lifting is not None:
            self.locks.free[hints.lifting] = False  # a ball rolling, not swinging
        if not self.anchored:  # planned targets (.footplan): the site locks and height pulls only
            pivots = {self.locks.tasks[k].site_id for k in np.flatnonzero(toes_only & self._pivot)}
            # a rigid foot rolling over its front edge: its pivot is pulled down only softly, so
            # the foot pitches over the edge rather than tipping onto its side (a weak pull lets
            # the pivot rise a little as the edge rolls)
            scale = self.options.pivot_cost / self.options.cost_z if self.options.cost_z > 0 else 0.0
            # (a hold moved onto a tipped foot's resting patch marks no site: never a pivot's)
            for t in tasks:
                if getattr(t, "site_id", None) in pivots:
                    t.set_cost(t.cost * scale)
            tasks = [t for t in tasks if getattr(t, "site_id", None) not in pivots or scale > 0]
            return out, tasks, hard, offsets
        held = {name: bool(labels.get(name, False)) for name in ("left_heel", "left_toe", "right_heel", "right_toe")}
        for site, e in zip(self.sites, engaged):
            held[self.site_label[site]] |= bool(e)
        for s, side in enumerate(("left", "right")):
            if side not in self.feet:
                continue
            ia, it, ra, rt, _ = self.feet[side]
            now_a = None if first else self._xy(data, ra)
            now_t = None if first else self._xy(data, rt)
            offsets[s] = self.anchors[side].step(
                held[f"{side}_heel"],
                held[f"{side}_toe"],
                positions[ia, :2],
                positions[it, :2],
                now_a,
                now_t,
                base=_toward_zero(self.root_offset, self.options.drift_correction),
            )
        # The body follows its planted feet: the root offset relaxes towards the mean
        # offset of the held feet (held in flight), so a source whose feet slide does
        # not stretch the stance leg and drag the pelvis.
        planted = [offsets[s] for s, side in enumerate(("left", "right")) if side in self.feet and self.anchors[side].held]
        if planted and self._root_alpha > 0:
            self.root_offset = self.root_offset + self._root_alpha * (np.mean(planted, axis=0) - self.root_offset)
        out[self._body, :2] += self.root_offset
        for s, side in enumerate(("left", "right")):
            if side not in self.feet:
                continue
            out[self.feet[side][4], :2] += offsets[s]
            if side in self.lengths and not labels.get(f"{side}_knee", False):  # a knee on the floor keeps its target
                ih, ik, ia2, l1, l2 = self.lengths[side]
                knee0 = positions[ik].copy()
                knee0[:2] += self.root_offset
                fwd = out[self.feet[side][1]] - out[self.feet[side][0]]
                out[ik] = knee_between(out[ih][None], out[ia2][None], knee0[None], l1, l2, fwd[None])[0]
        return out, tasks, hard, offsets
