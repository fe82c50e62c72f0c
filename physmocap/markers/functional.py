r"""Functional joint centres: centres of rotation fitted to the markers' motion.

For each segment, a rigid frame per frame from its markers (three or more points, some of
them joint centres already found, by weighted least squares: Kabsch / SVD, Arun et al. 1987)
against the segment's mean marker constellation (Procrustes mean over the frames where every
point is seen).  Then, proximal to distal, each joint's centre of rotation:

* **SCoRE** (Ehrig et al. 2006, J. Biomech. 39:2798) where the child segment has a frame of its
  own markers: the point fixed in both frames, :math:`\min_{c_p, c_c} \sum_t
  \| R_p(t) c_p + t_p(t) - R_c(t) c_c - t_c(t) \|^2` (linear least squares);
* else the closed-form **sphere fit** of Gamage & Lasenby (2002, J. Biomech. 35:87): every
  child marker, seen in the parent's frame, moves on a sphere about the centre:
  :math:`A c = b` with :math:`A = 2\sum_k \mathrm{cov}(v_k)`,
  :math:`b = \sum_k \overline{v_k |v_k|^2} - \bar v_k \overline{|v_k|^2}`.

Frames are chosen by how the joint moves, not by frame numbers: the relative rotation
(child direction in the parent's frame) is binned on a grid of a few degrees and one frame
per bin is kept, so a long static stretch does not outweigh a short range of motion; the
joint counts as exercised when the angular spread of those directions (98th percentile of
the pairwise angles) reaches :data:`MIN_SPREAD_DEG`.  A hinge (knee, elbow) determines its
centre only across the axis (SCoRE's known weakness): the direction(s) the data leave
undetermined take the regression estimate's component (:mod:`.joints`, Harrington 2007 for
hips), so a knee centre lies on the functional axis at the depth of the anatomical one.
A fit needs a parent frame whose rotation is determined: points spread off a line enough
that soft-tissue motion cannot turn it noticeably about its long axis (:data:`MAX_FRAME_ERROR`;
two skin markers and a joint centre nearly in a row, as on the CMU set's thigh, shank and
upper arm, do not).  A hinge's centre along its axis is never taken from the motion (:data:`HINGE_JOINTS`), and a
ball joint (hip, shoulder) or the wrist is fitted only when its motion spans two planes
(:data:`TWO_PLANE_JOINTS`: functional methods need multi-plane calibration movements, sources
there): a jumping or walking clip flexes the hip in one plane, and the regression is kept.
Frames whose fit residual exceeds three times the median are dropped and the fit repeated
once (marker glitches).  Where a joint is not exercised enough, its segments lack markers,
or the fit's residual is implausible, the regression centre is kept; every joint records its
method (``"functional (SCoRE, 412 frames, residual 6.1 mm)"`` or ``"regression (...)"``).

Segment lengths are then fixed for the clip (rigid skeleton): the median over frames of the
distance between consecutive centres.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import warn
from .joints import JointCentres, joint_centres
from .markerset import MarkerSet
from .recording import MarkerRecording, plain_label

__all__ = [
    "SEGMENT_ROLES",
    "FUNCTIONAL_JOINTS",
    "SegmentFrames",
    "Calibration",
    "kabsch",
    "kabsch_frames",
    "sphere_fit",
    "score_fit",
    "functional_joint_centres",
    "segment_markers",
]

# Where each threshold below comes from: a cited finding where one bears on it, else the
# engineering reason for the value (changing one changes the README's marker figures).
#: Minimum angular spread (degrees, 98th percentile of the pairwise angles between the child's
#: directions) of a joint's motion for a functional fit.  Range of motion is among what the
#: functional-method studies examine (Hicks & Richards 2005, Gait Posture 22:138, varied the
#: flexion-extension and abduction-adduction ranges of the fitted motion; Piazza et al. 2004
#: assessed the functional hip centre under reduced range of hip motion, the subject of its
#: title as Hicks & Richards cite it; its figures are not checked here).  The value is an
#: engineering choice: no source found gives one cut-off for all joints, and this spread is
#: measured on the child's direction, not as a goniometric angle.
MIN_SPREAD_DEG = 25.0
#: Fewest distinct poses (cells of the :data:`BIN` grid, about 3 degrees) a functional fit
#: uses.  An engineering choice, not from a paper: 30 poses give SCoRE 90 equations for its 6
#: unknowns (the sphere fit 30 per marker for 3), so the glitch-frame rejection (three times
#: the median gap) has a median to work with and no single pose decides the centre.
MIN_FRAMES = 30
#: Fewest distinct poses when the child segment has one marker (a sphere fit of one point: no
#: rigid frame to average the skin motion over).  An engineering choice, not from a paper:
#: :data:`MIN_FRAMES` times about 3, since one marker's soft-tissue motion (:data:`STA_SIGMA`)
#: enters the fit unaveraged where three markers would average it.
MIN_FRAMES_ONE_MARKER = 100
#: Largest fit residual (metres) still believed: SCoRE's half distance between the centre
#: seen from the parent and from the child, the sphere fit's RMS radial scatter.  The first is
#: the "joint gap error" of J. Biomech. Eng. 138(1):011004 (2016), which reports 12-19 mm for
#: functional hip centres over activities of daily living (13-34 mm for anatomical ones), and
#: soft-tissue motion at the hip reaches 20 mm or more (Ann. Biomed. Eng.,
#: doi:10.1007/s10439-015-1522-1, citing the skin-motion studies).  A residual of 3 cm is
#: beyond both: the fit then follows skin or a wrong marker, not a joint.  The margin above
#: 19-20 mm is an engineering choice.
MAX_RESIDUAL = 0.03
#: Largest distance (metres) a functional centre may lie from the regression estimate.  The
#: regression's own error is a few centimetres (Hicks & Richards 2005: 2.16 cm mean for the
#: predictive hip centre against ultrasound, 1.34 cm for the functional one; J. Biomech. Eng.
#: 2016 above: anatomical joint gap errors up to 34 mm); a functional centre 12 cm away (about
#: 3.5 times the largest of those) is a fit gone wrong, not a better estimate.  The factor is an
#: engineering choice: it only catches gross failures, the residual and rank tests the rest.
MAX_SHIFT = 0.12
#: Bin size (radians) of the pose grid used to pick frames.
BIN = 0.05
#: Most frames one fit uses (evenly drawn from the bins when more).
MAX_FRAMES = 800
#: Fewest frames, every point of a segment seen, that its mean constellation (the local shape
#: every frame's Kabsch fit aligns to) is averaged over; a recording shorter than this cannot
#: be calibrated.  An engineering choice, not from a paper: with 5 mm of soft-tissue motion
#: per marker (:data:`STA_SIGMA`) the mean of 10 frames places each point to about
#: 5 / sqrt(10) = 1.6 mm if the frames were independent (successive frames are not, so this
#: is a floor, not a target).
MIN_CONSTELLATION_FRAMES = 10
#: Joints whose centre a single plane of motion cannot place (ball joints, and the wrist's two
#: axes): fitted only when the motion also spans :data:`MIN_SECOND_PLANE_DEG` across its main
#: plane.  Sources: SCoRE needs complex multi-plane movements for an accurate hip centre, and
#: subjects with a limited hip range get a poor one (Ravera & Peterson, "A regularized
#: functional method to determine the hip joint center of rotation in subjects with limited
#: range of motion", J. Biomech.); functional methods are sensitive to the complexity of the
#: calibration movement (Meng, Childs & Buis 2019, "Evaluation of functional methods of joint
#: centre determination for quasi-planar movement"), and later studies (Siston & Delp 2006,
#: Kainz et al. 2015, as Ravera & Peterson cite them) found the multi-plane "star-arc"
#: movement that Camomilla et al. (2006, J. Biomech.) proposed the best calibration movement.
#: That the regression beats a one-plane functional fit is this module's reading of those
#: findings, not a figure from them.
TWO_PLANE_JOINTS = ("hip", "shoulder", "wrist")
#: Smallest extent (degrees) across the main plane of motion for :data:`TWO_PLANE_JOINTS`.  An
#: engineering choice, not from a paper: no source found gives a second-plane threshold.
MIN_SECOND_PLANE_DEG = 20.0
#: Soft-tissue motion (metres, RMS) of a skin marker relative to its bone: 5 mm is at the low
#: end of what Leardini et al. (2005, Gait Posture 21:212) review (up to 2-3 cm on the thigh).
STA_SIGMA = 0.005
#: Largest displacement (metres) of the child's markers, in the parent's frame, that the
#: parent frame's own uncertainty may cause: the rotation about the parent's long axis is
#: uncertain by about ``STA_SIGMA / spread`` radians (:attr:`SegmentFrames.spread`;
#: Cappozzo et al. 1997, Gait Posture 5:1, on cluster size), which moves a child marker at
#: distance ``lever`` from that axis by ``lever * STA_SIGMA / spread`` (:func:`_lever`).
MAX_FRAME_ERROR = 0.02
#: Hinges: the centre along the flexion axis is never determined by the motion (any point of
#: the axis fits a pure hinge equally; soft-tissue wobble only pretends to fix it), so it
#: always keeps the regression's component: the functional axis at the anatomical depth
#: (the projection of the anatomical centre onto the functional axis).
HINGE_JOINTS = ("knee", "elbow", "ankle")
#: The lateral marker role of each hinge (``{s}`` prefix added per side).
LATERAL_ROLE = {"knee": "KNE", "ankle": "ANK", "elbow": "ELB"}
#: Largest angle (degrees) between a fitted hinge axis and the anatomical medio-lateral line
#: (lateral marker to the anatomical centre): the knee's flexion axis lies close to the
#: transepicondylar axis (Churchill et al. 1998, Clin. Orthop. 356:111), the ankle's
#: talocrural axis close to the line through the malleoli tips (Inman 1976), the elbow's
#: through the epicondyles; an axis far off is a fit to skin motion, not the joint.
MAX_HINGE_AXIS_DEG = 30.0

#: Segment -> marker roles on it (``{s}`` the side letter).  Cluster markers without a role
#: are attached by :data:`LABEL_HINTS` or by rigidity (:func:`segment_markers`).
SEGMENT_ROLES: dict[str, tuple[str, ...]] = {
    "pelvis": ("LASI", "RASI", "LPSI", "RPSI", "SACR"),
    "thorax": ("C7", "T10", "CLAV", "STRN"),
    "head": ("LFHD", "RFHD", "LBHD", "RBHD"),
    **{f"{side}_{seg}": tuple(f"{s}{r}" for r in roles)
       for s, side in (("L", "left"), ("R", "right"))
       for seg, roles in (("clavicle", ("SHO",)), ("thigh", ("THI", "KNE", "KNEM")), ("shank", ("TIB", "ANK", "ANKM")),
                          ("foot", ("HEE", "TOE")), ("upper_arm", ("ELB", "ELBM")), ("forearm", ("WRA", "WRB")),
                          ("hand", ("FIN",)))},
}

#: Label stems (after the side letter) of common cluster markers that play no joint-centre
#: role, and their segment: CMU ``LUPA`` / ``LFRM`` / ``LMT5`` / ``RBAC``, Plug-in Gait-like
#: ``LMT1``, ``LARM``...
LABEL_HINTS: dict[str, str] = {
    "UPA": "upper_arm", "UPPERARM": "upper_arm", "ARM": "upper_arm", "HUM": "upper_arm",
    "FRM": "forearm", "FOREARM": "forearm", "FA": "forearm",
    "MT5": "foot", "MT1": "foot", "MET5": "foot", "MET1": "foot", "FM5": "foot", "FM1": "foot",
    "BAC": "thorax", "BACK": "thorax", "SCAP": "thorax", "SHB": "thorax",
    "THI2": "thigh", "TIB2": "shank", "SHN2": "shank",
}

#: joint -> (parent segment, child segment, virtual point the child's frame gains).
FUNCTIONAL_JOINTS: dict[str, tuple[str, str]] = {
    **{f"{side}_{j}": (f"{side}_{p}" if p not in ("pelvis", "thorax") else p, f"{side}_{c}")
       for side in ("left", "right")
       for j, p, c in (("hip", "pelvis", "thigh"), ("knee", "thigh", "shank"), ("ankle", "shank", "foot"),
                       ("shoulder", "clavicle", "upper_arm"), ("elbow", "upper_arm", "forearm"),
                       ("wrist", "forearm", "hand"))},
}

#: Consecutive centres whose distance is a segment length (canonical parent, child).
LENGTH_PAIRS = tuple(
    (f"{side}_{a}", f"{side}_{b}") for side in ("left", "right")
    for a, b in (("hip", "knee"), ("knee", "ankle"), ("shoulder", "elbow"), ("elbow", "wrist"))
) + (("left_hip", "right_hip"), ("left_shoulder", "right_shoulder"))


@dataclass(frozen=True)
class SegmentFrames:
    """A segment's rigid frame per frame: ``world = R @ local + t``.

    Attributes:
        R: ``(F, 3, 3)`` rotations (NaN where fewer than three points are seen).
        t: ``(F, 3)`` origins.
        ok: ``(F,)`` True where the frame is defined.
        local: ``(K, 3)`` the points' positions in the frame (Procrustes mean).
        points: Names of the K points (marker labels or joint names).
        rms: ``(F,)`` RMS distance (metres) of the seen points from the fitted constellation.
        borrowed_spread: The :attr:`spread` of the frame whose rotation this one borrows
            (the clavicle's, from the thorax), else None.
    """

    R: np.ndarray
    t: np.ndarray
    ok: np.ndarray
    local: np.ndarray
    points: tuple[str, ...]
    rms: np.ndarray
    borrowed_spread: float | None = None

    @property
    def spread(self) -> float:
        """How far (metres) the points spread off their principal line: the root sum of
        squares of their distances from it (the 2nd and 3rd singular values of the centred
        constellation).  A rotation about that line moves the points by this much per radian,
        so skin-marker noise ``sigma`` leaves it uncertain by about ``sigma / spread``
        radians (near 0: two markers and a joint centre in a row)."""
        if self.borrowed_spread is not None:
            return self.borrowed_spread
        L = self.local - self.local.mean(0)
        if len(L) < 3:
            return 0.0
        sv = np.linalg.svd(L, compute_uv=False)
        return float(np.hypot(sv[1], sv[2]))

    def to_local(self, X: np.ndarray) -> np.ndarray:
        """``(F, 3)`` world points into this frame (NaN where either is undefined)."""
        return np.einsum("fji,fj->fi", self.R, X - self.t)

    def to_world(self, c: np.ndarray) -> np.ndarray:
        """A local point ``(3,)`` or ``(F, 3)`` to world, per frame."""
        c = np.broadcast_to(c, self.t.shape)
        return np.einsum("fij,fj->fi", self.R, c) + self.t


@dataclass(frozen=True)
class Calibration(JointCentres):
    """Joint centres (functional where the motion allows, else regression) and the rest.

    Attributes:
        positions: Canonical joint -> ``(F, 3)`` centres (metres, the file's axes).
        method: Canonical joint -> how its centre was found.
        lengths: ``(joint, joint)`` -> metres, fixed for the clip (median over frames).
        frames: Segment -> :class:`SegmentFrames` (segments with a frame).
        segment_of: Marker index -> segment it is attached to.
        local_centres: Joint -> its centre in the parent segment's frame (functional ones).
    """

    lengths: dict[tuple[str, str], float] = field(default_factory=dict)
    frames: dict[str, SegmentFrames] = field(default_factory=dict)
    segment_of: dict[int, str] = field(default_factory=dict)
    local_centres: dict[str, np.ndarray] = field(default_factory=dict)


# -- rigid frames ------------------------------------------------------------------
def kabsch(A: np.ndarray, X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Weighted least-squares rigid fit per frame (Kabsch / SVD, Arun et al. 1987).

    Args:
        A: ``(K, 3)`` points in the local frame (metres).
        X: ``(F, K, 3)`` the same points seen per frame (metres; NaN allowed where ``w`` is 0).
        w: ``(F, K)`` non-negative weights.
    Returns:
        ``(R, t)``: ``(F, 3, 3)`` proper rotations and ``(F, 3)`` translations (metres)
        minimising :math:`\sum_k w_k \| R A_k + t - X_k \|^2` per frame.
    """
    Xz = np.where(w[..., None] > 0, X, 0.0)
    sw = w.sum(1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        ca = (w @ A) / sw  # (F, 3)
        cx = np.einsum("fk,fkj->fj", w, Xz) / sw
    Ac = A[None] - ca[:, None]
    Xc = Xz - cx[:, None]
    H = np.einsum("fk,fki,fkj->fij", w, Xc, Ac)  # sum w x a^T
    H = np.nan_to_num(H)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones((len(X), 3))
    D[:, 2] = np.where(d == 0, 1.0, d)
    R = (U * D[:, None, :]) @ Vt
    t = cx - np.einsum("fij,fj->fi", R, ca)
    return R, t


def kabsch_frames(points: np.ndarray, names: tuple[str, ...] | list[str], min_points: int = 3) -> SegmentFrames | None:
    """A segment's frames from ``(F, K, 3)`` point trajectories (NaN = unseen).

    The constellation is the Procrustes mean over the frames where every point is seen (at
    least :data:`MIN_CONSTELLATION_FRAMES`; points seen too rarely are dropped first); each frame is then the weighted Kabsch fit
    of the seen points (at least ``min_points``, not collinear).  None if no frame can be built.
    """
    P = np.asarray(points, dtype=float)
    names = list(names)
    F = P.shape[0]
    seen = np.all(np.isfinite(P), axis=2)
    keep = np.arange(P.shape[1])
    while len(keep) >= min_points:
        full = np.all(seen[:, keep], axis=1)
        if full.sum() >= MIN_CONSTELLATION_FRAMES:
            break
        worst = keep[np.argmin(seen[:, keep].sum(0))]
        keep = keep[keep != worst]
    else:
        return None
    P, seen, names = P[:, keep], seen[:, keep], [names[k] for k in keep]
    full_idx = np.flatnonzero(np.all(seen, axis=1))
    if len(full_idx) > 400:
        full_idx = full_idx[np.linspace(0, len(full_idx) - 1, 400).astype(int)]
    S = P[full_idx]  # (n, K, 3)
    ref = S[0] - S[0].mean(0)
    if np.linalg.svd(ref, compute_uv=False)[1] < 1e-3:  # collinear points: no frame
        return None
    for _ in range(3):  # Procrustes mean
        R, t = kabsch(ref, S, np.ones(S.shape[:2]))
        aligned = np.einsum("fji,fkj->fki", R, S - t[:, None])
        ref = aligned.mean(0)
        ref = ref - ref.mean(0)
    w = seen.astype(float)
    R, t = kabsch(ref, P, w)
    n = seen.sum(1)
    ok = n >= min_points
    # collinear seen points (e.g. two markers and a centre on one line) do not fix a rotation
    sv = np.zeros(F)
    for k in np.flatnonzero(ok & (n < P.shape[1])):
        sv[k] = np.linalg.svd(ref[seen[k]] - ref[seen[k]].mean(0), compute_uv=False)[1]
    ok &= (n == P.shape[1]) | (sv > 5e-3)
    with np.errstate(invalid="ignore"):
        fit = np.einsum("fij,kj->fki", R, ref) + t[:, None]
        d2 = np.where(seen, np.sum((fit - np.where(seen[..., None], P, 0.0)) ** 2, -1), 0.0)
        rms = np.sqrt(d2.sum(1) / np.maximum(n, 1))
    R[~ok] = np.nan
    t[~ok] = np.nan
    rms[~ok] = np.nan
    return SegmentFrames(R=R, t=t, ok=ok, local=ref, points=tuple(names), rms=rms)


# -- centre-of-rotation fits -----------------------------------------------------------
def _regularised_solve(A: np.ndarray, b: np.ndarray, prior: np.ndarray, rel: float = 0.02,
                       min_eig: float = 0.0, max_rank: int | None = None) -> tuple[np.ndarray, int]:
    """Least-squares solution of ``A x = b`` (A symmetric PSD) closest to ``prior`` along the
    directions ``A`` barely determines (eigenvalues below ``rel`` times the largest, or below
    ``min_eig``, and all but the ``max_rank`` best determined); returns ``(x, number of
    determined directions)``."""
    lam, V = np.linalg.eigh(A)  # ascending
    good = (lam > rel * max(lam.max(), 1e-300)) & (lam > min_eig)
    if max_rank is not None:
        good[: max(len(lam) - max_rank, 0)] = False
    x = prior.copy()
    r = b - A @ prior
    for i in np.flatnonzero(good):
        x = x + V[:, i] * (V[:, i] @ r) / lam[i]
    return x, int(good.sum())


#: Largest statistical uncertainty (metres, one standard error from the fit's own residual) of a
#: fitted centre along a direction for that direction to count as determined by the motion
#: (else the regression's component is kept).  An engineering choice, not from a paper: 2 mm
#: is a tenth of the 2 cm the regression itself is typically off (:data:`MAX_SHIFT`'s sources),
#: so a direction kept from the fit is far better known than the one it replaces; a looser
#: bound lets the near-singular directions of a hinge or a small motion move the centre by
#: skin wobble.
MAX_STD = 0.002


def sphere_fit(V: list[np.ndarray], prior: np.ndarray, max_rank: int = 3) -> tuple[np.ndarray, float, int]:
    """Common centre of several markers each moving on a sphere (Gamage & Lasenby 2002).

    Args:
        V: Per marker, ``(N_k, 3)`` positions in the parent's frame (finite rows only).
        prior: Centre used along the directions the data leave undetermined.
        max_rank: Most directions the motion may determine (2 for a hinge: its axis never is).
    Returns:
        ``(centre, RMS radial residual in metres, determined directions)``.

    A direction counts as determined when the fit's standard error along it (from the
    radial residual, as ordinary least squares on the linear system) is below
    :data:`MAX_STD` and its eigenvalue is at least 1 % of the largest.
    """
    V = [v for v in V if len(v) >= 4]
    A = np.zeros((3, 3))
    b = np.zeros(3)
    n = 0
    for v in V:
        m = v.mean(0)
        q = np.sum(v * v, 1)
        A += 2.0 * np.cov(v.T, bias=True)
        b += (v * q[:, None]).mean(0) - m * q.mean()
        n += len(v)
    if not V:
        return np.asarray(prior, float), np.inf, 0

    def residual(c):
        res, rad = [], []
        for v in V:
            d = np.linalg.norm(v - c, axis=1)
            res.append(d - d.mean())
            rad.append(d.mean())
        return float(np.sqrt(np.mean(np.concatenate(res) ** 2))), float(np.mean(rad))

    c, _ = _regularised_solve(A, b, np.asarray(prior, float), 0.01, 0.0, max_rank)
    r, radius = residual(c)
    # per-marker equations are averaged over N_k samples: sigma_b ~ 2 radius sigma_r / sqrt(N_k)
    sigma_y = 2.0 * radius * max(r, 2e-4)
    min_eig = len(V) * sigma_y**2 / (MAX_STD**2 * max(n / len(V), 1.0))
    c, rank = _regularised_solve(A, b, np.asarray(prior, float), 0.01, min_eig, max_rank)
    r, _ = residual(c)
    return c, r, rank


def score_fit(Rp, tp, Rc, tc, prior_p, prior_c, max_rank: int = 6) -> tuple[np.ndarray, np.ndarray, float, int]:
    """SCoRE (Ehrig et al. 2006): the point fixed in both frames.

    Args:
        Rp, tp, Rc, tc: ``(N, 3, 3)`` and ``(N, 3)`` parent and child frames.
        prior_p, prior_c: The prior centre in each frame (for undetermined directions).
        max_rank: Most of the 6 directions the motion may determine (5 for a hinge: sliding
            the point along the axis in both frames at once never changes the fit).
    Returns:
        ``(c_parent, c_child, RMS distance in metres between the two world estimates / 2,
        determined directions of 6)``.
    """
    M = np.concatenate([Rp, -Rc], axis=2)  # (N, 3, 6)
    y = tc - tp
    A = np.einsum("nki,nkj->ij", M, M)
    b = np.einsum("nki,nk->i", M, y)
    prior = np.concatenate([prior_p, prior_c])

    def solve(min_eig):
        x, rank = _regularised_solve(A, b, prior, 0.01, min_eig, max_rank)
        gap = np.einsum("nij,j->ni", Rp, x[:3]) + tp - np.einsum("nij,j->ni", Rc, x[3:]) - tc
        return x, rank, float(np.sqrt(np.mean(np.sum(gap**2, 1)) / 3.0))

    x, _, sigma = solve(0.0)
    # a direction is determined when the fit's standard error along it, sigma / sqrt(eigenvalue)
    # (ordinary least squares), is below MAX_STD
    x, rank, sigma = solve(max(sigma, 2e-4) ** 2 / MAX_STD**2)
    return x[:3], x[3:], sigma * np.sqrt(3.0) / 2.0, rank


def _pick_frames(dirs: np.ndarray, usable: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Frames spread over the poses: one per bin of the pose descriptor ``dirs`` ``(F, D)``
    (unit-vector components, radians-ish); the angular spread in degrees (98th percentile of
    the pairwise angles of the first direction) and the motion's extent across its main
    plane (:func:`_minor_extent`)."""
    idx = np.flatnonzero(usable)
    if len(idx) < MIN_FRAMES:
        return idx, 0.0, 0.0
    keys = np.floor(dirs[idx] / BIN).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    chosen = idx[np.sort(first)]
    if len(chosen) > MAX_FRAMES:
        chosen = chosen[np.linspace(0, len(chosen) - 1, MAX_FRAMES).astype(int)]
    sub = chosen if len(chosen) <= 300 else chosen[np.linspace(0, len(chosen) - 1, 300).astype(int)]
    u = dirs[sub, :3]
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(u @ u.T, -1, 1)))
    spread = float(np.percentile(ang, 98)) if len(sub) > 1 else 0.0
    return chosen, spread, _minor_extent(dirs[chosen, :3])


def _minor_extent(u: np.ndarray) -> float:
    """Extent (degrees, 2nd to 98th percentile) of unit directions ``u`` ``(N, 3)`` across the
    plane they mostly sweep: the directions are seen from their mean as angles along the two
    principal tangent axes, and the smaller extent is returned (near 0 for a hinge)."""
    if len(u) < 3:
        return 0.0
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    m = u.mean(0)
    m = m / max(np.linalg.norm(m), 1e-12)
    T = u - np.outer(u @ m, m)
    _, _, Vt = np.linalg.svd(T - T.mean(0), full_matrices=False)
    ang = np.degrees(np.arctan2(T @ Vt[1], u @ m))
    return float(np.percentile(ang, 98) - np.percentile(ang, 2))


# -- marker attachment -----------------------------------------------------------------
def _side_stem(label: str) -> tuple[str | None, str]:
    """``(side or None, stem)`` of a label: a leading ``L``/``R`` (``LUPA``), or a trailing
    capital ``L``/``R`` (``ThighL``); a trailing lowercase ``l m r u`` (``ARMl``) qualifies the
    landmark (lateral, medial, radial, ulnar), is not a side, and is dropped from the stem."""
    p = plain_label(label)
    raw = re.sub(r"[^A-Za-z0-9]", "", label.rsplit(":", 1)[-1])
    if len(p) > 1 and p[0] in "LR":
        return ("left" if p[0] == "L" else "right"), p[1:]
    if len(p) > 1 and raw[-1:] in ("L", "R") and p[:-1].isalpha():
        return ("left" if p[-1] == "L" else "right"), p[:-1]
    if len(p) > 2 and raw[-1:] in ("l", "m", "r", "u") and raw[-2:-1].isupper():
        return None, p[:-1]
    return None, p


def segment_markers(rec: MarkerRecording, ms: MarkerSet) -> dict[int, str]:
    """Marker index -> segment for the markers playing a role, and cluster markers named
    in :data:`LABEL_HINTS` (``LUPA`` -> ``left_upper_arm``, ``RBAC`` -> ``thorax``); a
    hinted marker whose label has no side takes the side it is on (:mod:`.sides`)."""
    from .sides import lateral_offsets, side_of

    out: dict[int, str] = {}
    for seg, roles in SEGMENT_ROLES.items():
        for r in roles:
            if r in ms.roles:
                out[ms.roles[r]] = seg
    used = set(ms.roles.values())
    offsets: np.ndarray | None = None
    for i, lab in enumerate(rec.labels):
        if i in used:
            continue
        side, stem = _side_stem(lab)
        seg = LABEL_HINTS.get(stem)
        if seg is None:
            continue
        if seg in SEGMENT_ROLES:
            out[i] = seg
            continue
        if side is None:
            offsets = lateral_offsets(rec, ms) if offsets is None else offsets
            side = None if offsets is None else side_of(offsets[i])
        if side is not None:
            out[i] = f"{side}_{seg}"
    return out


def attach_by_rigidity(rec: MarkerRecording, frames: dict[str, SegmentFrames], taken: dict[int, str],
                       limit: float = 0.02) -> dict[int, str]:
    """Markers not yet attached, each to the segment in whose frame it moves least (RMS
    scatter below ``limit`` metres over at least half the clip), provided that segment is
    the only one it is rigid on: its scatter in every other segment's frame must be at
    least ``limit`` and twice the best.  A marker rigid on several segments (a take where
    those segments hardly move relative to each other, a prop held still) cannot be told
    apart and stays unattached, and so listed as ignored."""
    out = dict(taken)
    P = rec.positions
    for i in range(P.shape[1]):
        if i in out:
            continue
        scatter = []
        for seg, fr in frames.items():
            v = fr.to_local(P[:, i])
            ok = np.all(np.isfinite(v), 1)
            if ok.sum() < max(30, 0.5 * rec.num_frames):
                continue
            scatter.append((float(np.sqrt(np.mean(np.sum((v[ok] - np.median(v[ok], 0)) ** 2, 1)))), seg))
        if not scatter:
            continue
        scatter.sort()
        best, seg = scatter[0]
        second = scatter[1][0] if len(scatter) > 1 else np.inf
        if best < limit and second >= max(limit, 2.0 * best):
            out[i] = seg
    return out


# -- the calibration --------------------------------------------------------------------
def _nanmedian_rows(X: np.ndarray) -> np.ndarray | None:
    ok = np.all(np.isfinite(X), 1)
    return np.median(X[ok], 0) if ok.any() else None


def functional_joint_centres(rec: MarkerRecording, ms: MarkerSet, regression: JointCentres | None = None) -> Calibration:
    """Joint centres of a recording: functional where the clip exercises the joint, else the
    regression of :func:`.joints.joint_centres`; segment frames, marker attachment and the
    clip's fixed segment lengths (see the module docstring)."""
    reg = regression if regression is not None else joint_centres(rec, ms)
    P = rec.positions
    positions = {k: v.copy() for k, v in reg.positions.items()}
    method = {k: f"regression ({v})" for k, v in reg.method.items()}
    seg_of = segment_markers(rec, ms)
    members: dict[str, list[int]] = {}
    for i, s in seg_of.items():
        members.setdefault(s, []).append(i)
    frames: dict[str, SegmentFrames] = {}
    local_centres: dict[str, np.ndarray] = {}

    def own_frame(seg: str, extra: tuple[str, ...] = ()) -> SegmentFrames | None:
        idx = members.get(seg, [])
        pts = [P[:, i] for i in idx] + [positions[j] for j in extra if j in positions]
        names = [rec.labels[i] for i in idx] + [j for j in extra if j in positions]
        if len(pts) < 3:
            return None
        return kabsch_frames(np.stack(pts, 1), names)

    for seg in ("pelvis", "thorax", "head"):
        fr = own_frame(seg)
        if fr is not None:
            frames[seg] = fr
    # the acromion marker carries the shoulder girdle: the thorax's orientation at the marker
    for side, s in (("left", "L"), ("right", "R")):
        if "thorax" in frames and f"{s}SHO" in ms.roles:
            th = frames["thorax"]
            sho = P[:, ms.roles[f"{s}SHO"]]
            ok = th.ok & np.all(np.isfinite(sho), 1)
            t = np.where(ok[:, None], sho, np.nan)
            frames[f"{side}_clavicle"] = SegmentFrames(R=th.R, t=t, ok=ok, local=np.zeros((1, 3)),
                                                       points=(rec.labels[ms.roles[f"{s}SHO"]],), rms=th.rms,
                                                       borrowed_spread=th.spread)

    order = ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")
    for j in order:
        for side in ("left", "right"):
            joint = f"{side}_{j}"
            parent, child = FUNCTIONAL_JOINTS[joint]
            proximal = {"knee": f"{side}_hip", "ankle": f"{side}_knee", "elbow": f"{side}_shoulder",
                        "wrist": f"{side}_elbow"}.get(j)
            if parent not in frames and proximal is not None:
                fr = own_frame(parent, (proximal,))
                if fr is not None:
                    frames[parent] = fr
            lat = ms.roles.get(f"{side[0].upper()}{LATERAL_ROLE.get(j, '')}")
            why, fit = _fit_joint(rec, joint, frames.get(parent), own_frame(child), members.get(child, []), positions.get(joint),
                                  None if lat is None else P[:, lat])
            if fit is None:
                if why:
                    method[joint] = (method[joint] + f"; not functional: {why}") if joint in method else f"none ({why})"
                continue
            c_world, c_local, how = fit
            if joint in positions:  # frames where the parent frame is unseen keep the regression centre
                c_world = np.where(np.isfinite(c_world), c_world, positions[joint])
            positions[joint] = c_world
            method[joint] = how
            local_centres[joint] = c_local
    # distal segments' frames, with their proximal centre, for the attachment and the solve
    for side in ("left", "right"):
        for seg, prox in (("thigh", "hip"), ("shank", "knee"), ("foot", "ankle"), ("upper_arm", "shoulder"),
                          ("forearm", "elbow"), ("hand", "wrist")):
            name = f"{side}_{seg}"
            if name not in frames:
                fr = own_frame(name, (f"{side}_{prox}",))
                if fr is not None:
                    frames[name] = fr
    lengths: dict[tuple[str, str], float] = {}
    for a, b in LENGTH_PAIRS:
        if a in positions and b in positions:
            d = np.linalg.norm(positions[a] - positions[b], axis=1)
            d = d[np.isfinite(d)]
            if d.size:
                lengths[(a, b)] = float(np.median(d))
    return Calibration(positions=positions, method=method, lengths=lengths, frames=frames,
                       segment_of=seg_of, local_centres=local_centres)


def _lever(parent: SegmentFrames, V: list[np.ndarray], prior: np.ndarray) -> float:
    """Typical distance (metres, median over the child's markers and frames) of the child's
    markers ``V`` (parent frame) from the parent's long axis (its constellation's principal
    line), the arm by which a turn of the parent frame about that axis moves them; from the
    ``prior`` centre for a frame that borrows its rotation."""
    if parent.borrowed_spread is not None or len(parent.local) < 3:
        d = [np.linalg.norm(v - prior, axis=1) for v in V]
    else:
        c0 = parent.local.mean(0)
        a = np.linalg.svd(parent.local - c0)[2][0]
        d = [np.linalg.norm((v - c0) - np.outer((v - c0) @ a, a), axis=1) for v in V]
    d = np.concatenate(d)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else float("nan")


def _axis_deviation(parent: SegmentFrames, V: list[np.ndarray], lateral: np.ndarray | None,
                    prior_world: np.ndarray | None) -> float | None:
    """Angle (degrees, 0-90) between a hinge's axis, seen from the parent, and the anatomical
    medio-lateral line from the lateral marker to the anatomical centre (both in the parent's
    frame, medians over the frames); None without them.  The axis is the normal of the planes
    the child's markers sweep about it: the least direction of their pooled covariance."""
    if lateral is None or prior_world is None:
        return None
    ml = _nanmedian_rows(parent.to_local(prior_world) - parent.to_local(lateral))
    C = np.zeros((3, 3))
    for v in V:
        v = v[np.all(np.isfinite(v), 1)]
        if len(v) >= 4:
            C += np.cov(v.T, bias=True)
    if ml is None or not np.any(C) or np.linalg.norm(ml) < 1e-3:
        return None
    axis = np.linalg.eigh(C)[1][:, 0]
    return float(np.degrees(np.arccos(min(1.0, abs(float(axis @ ml)) / np.linalg.norm(ml)))))


def _fit_joint(rec, joint, parent: SegmentFrames | None, child: SegmentFrames | None, child_markers: list[int],
               regression: np.ndarray | None, lateral: np.ndarray | None = None):
    """``(why not, None)`` or ``("", (world centres (F, 3), centre in the parent frame, method))``."""
    if parent is None:
        return f"too few markers on {FUNCTIONAL_JOINTS[joint][0]} for a rigid frame (3 points needed)", None
    P = rec.positions
    prior_w = regression
    prior = _nanmedian_rows(parent.to_local(prior_w)) if prior_w is not None else None
    V = [parent.to_local(P[:, i]) for i in child_markers]
    if not V:
        return f"no marker on {FUNCTIONAL_JOINTS[joint][1]}", None
    if prior is None:  # no regression centre: start from the parent frame's points' far end
        allv = np.concatenate([v[np.all(np.isfinite(v), 1)] for v in V]) if V else np.zeros((0, 3))
        if not len(allv):
            return "the child's markers are never seen with the parent's", None
        prior = allv.mean(0)
    lever = _lever(parent, V, prior)
    if np.isfinite(lever) and lever * STA_SIGMA > MAX_FRAME_ERROR * parent.spread:
        return (f"the {FUNCTIONAL_JOINTS[joint][0]} frame is too narrow ({', '.join(parent.points)} spread "
                f"{100 * parent.spread:.1f} cm off a line: 5 mm of skin motion would turn it about its long axis "
                f"and move the child's markers about {100 * lever * STA_SIGMA / max(parent.spread, 1e-9):.0f} cm)"), None
    # pose descriptor: directions of the child's markers from the prior centre, parent frame
    dirs = []
    for v in V:
        u = v - prior
        dirs.append(u / np.linalg.norm(u, axis=1, keepdims=True))
    D = np.concatenate(dirs, 1)
    use_score = child is not None and len(child_markers) >= 3
    usable = parent.ok & np.all(np.isfinite(D), 1)
    if use_score:
        usable &= child.ok
    chosen, spread, minor = _pick_frames(np.nan_to_num(D), usable)
    if len(chosen) < MIN_FRAMES:
        return f"the parent and child are seen together in only {len(chosen)} distinct poses ({MIN_FRAMES} needed)", None
    if len(child_markers) == 1 and len(chosen) < MIN_FRAMES_ONE_MARKER:
        return (f"one marker on the child segment, seen in only {len(chosen)} distinct poses "
                f"({MIN_FRAMES_ONE_MARKER} needed)"), None
    if spread < MIN_SPREAD_DEG:
        return f"the joint moves only {spread:.0f} degrees (a functional fit needs {MIN_SPREAD_DEG:.0f})", None
    jkind = joint.split("_", 1)[1]
    if jkind in TWO_PLANE_JOINTS and minor < MIN_SECOND_PLANE_DEG:
        return (f"the motion stays in one plane ({minor:.0f} degrees across it; a {jkind} centre needs "
                f"{MIN_SECOND_PLANE_DEG:.0f})"), None
    hinge = jkind in HINGE_JOINTS
    sel = chosen
    for _ in range(2):  # fit, drop glitch frames, refit
        if use_score:
            prior_c = _nanmedian_rows(child.to_local(parent.to_world(prior))[sel])
            if prior_c is None:
                return "no child frame", None
            cp, cc, res, rank = score_fit(parent.R[sel], parent.t[sel], child.R[sel], child.t[sel], prior, prior_c,
                                          5 if hinge else 6)
            gap = np.linalg.norm(parent.to_world(cp)[sel] - child.to_world(cc)[sel], axis=1)
        else:
            vs = [v[sel][np.all(np.isfinite(v[sel]), 1)] for v in V]
            cp, res, rank = sphere_fit(vs, prior, 2 if hinge else 3)
            gap = np.zeros(len(sel))
            for v in V:
                d = np.linalg.norm(v[sel] - cp, axis=1)
                ok = np.isfinite(d)
                if ok.sum():
                    gap = np.maximum(gap, np.where(ok, np.abs(d - np.median(d[ok])), 0.0))
        keep = gap <= 3.0 * max(np.median(gap), 1e-4)
        if keep.all():
            break
        sel = sel[keep]
    kind = "SCoRE" if use_score else "sphere fit"
    if hinge:
        dev = _axis_deviation(parent, [v[sel] for v in V], lateral, regression)
        if dev is not None and dev > MAX_HINGE_AXIS_DEG:
            return (f"the fitted hinge axis is {dev:.0f} degrees off the line from the lateral marker to the "
                    f"anatomical centre (at most {MAX_HINGE_AXIS_DEG:.0f}): a fit to skin motion"), None
    if res > MAX_RESIDUAL:
        return f"{kind} residual {1000 * res:.0f} mm is too large", None
    if regression is not None and np.linalg.norm(cp - prior) > MAX_SHIFT:
        return f"{kind} centre {100 * np.linalg.norm(cp - prior):.0f} cm from the anatomical estimate", None
    axis_note = "" if rank == (6 if use_score else 3) else ", axis depth from regression"
    how = f"functional ({kind}, {len(sel)} frames, residual {1000 * res:.1f} mm{axis_note})"
    return "", (parent.to_world(cp), cp, how)


def warn_fallbacks(cal: Calibration, source) -> None:
    """One warning naming the limb joints left to the regression, with the reason."""
    weak = [f"{j} ({m.split('not functional: ', 1)[1]})" for j, m in cal.method.items()
            if j in FUNCTIONAL_JOINTS and "not functional:" in m]
    if weak:
        warn(f"{source}: joint centres from the anatomical regression, not the motion: " + "; ".join(weak))
