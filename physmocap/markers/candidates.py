"""Which marker plays a role that two different labels claim (``LKNE`` and ``LFLE`` are both
the lateral knee), chosen from the recording rather than by file order.

A candidate is scored by its *consistent frames*: frames where it is seen and its distance
to every other marker of the role's segment seen in that frame is within
:data:`RIGID_TOLERANCE` of that distance's median over the clip (markers on one rigid
segment keep their distances; a mislabelled, ghost or loose marker does not).  Gaps and
rigidity are counted in one unit: a frame missing or off is a frame the marker cannot be
trusted.  The candidate with the most consistent frames plays the role; ties go to the
smaller median deviation, then to the first in the file.  A marker set file that names the
role decides instead (:func:`.markerset.detect_marker_set` then keeps no candidates).

Distances see a jump along the line to another marker fully and one across it only in part
(a jump ``h`` across a distance ``d`` changes it by about ``h**2 / (2 d)``): with three or
more other markers on the segment every direction is covered; with one, only large jumps
across it count.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import warn
from .markerset import MarkerSet, unused_labels
from .recording import MarkerRecording

__all__ = ["RIGID_TOLERANCE", "CandidateScore", "score_candidate", "choose_candidates"]

#: How far (metres) a marker's distance to another marker of its segment may stray from its
#: median over the clip and the frame still count as consistent.  The same 2 cm as
#: :func:`.functional.attach_by_rigidity`'s bound on the scatter of a marker rigid on its
#: segment, an engineering choice: well above the millimetres of camera noise, so skin motion
#: alone rarely fails a well-placed marker, and far below the decimetres by which a swapped
#: or ghost label jumps.
RIGID_TOLERANCE = 0.02


@dataclass(frozen=True)
class CandidateScore:
    """How well one candidate marker holds its role.

    Attributes:
        index: The marker.
        seen: Frames where it is valid.
        consistent: Frames where it is valid and rigid with its segment's other markers
            (:data:`RIGID_TOLERANCE`).
        deviation_m: Median absolute deviation (metres) of its distances to those markers
            from their medians; None when no other marker of the segment is seen with it.
    """

    index: int
    seen: int
    consistent: int
    deviation_m: float | None

    def key(self) -> tuple[int, float, int]:
        """Sort key, best first: most consistent frames, smallest deviation, first in the file."""
        return (-self.consistent, np.inf if self.deviation_m is None else self.deviation_m, self.index)

    def describe(self, labels: tuple[str, ...], frames: int) -> str:
        """``"LFLE: 2700 of 2751 frames consistent (2710 seen, 0.4 cm median deviation)"``."""
        dev = "no other marker of its segment seen with it" if self.deviation_m is None else \
            f"{self.deviation_m * 100:.1f} cm median deviation"
        return f"{labels[self.index]}: {self.consistent} of {frames} frames consistent ({self.seen} seen, {dev})"


def score_candidate(rec: MarkerRecording, index: int, partners: list[int]) -> CandidateScore:
    """Score marker ``index`` against ``partners``, the other markers of its segment
    (module docstring)."""
    P = rec.positions
    seen = np.all(np.isfinite(P[:, index]), axis=1)
    if not partners:
        return CandidateScore(index, int(seen.sum()), int(seen.sum()), None)
    D = np.linalg.norm(P[:, partners] - P[:, index, None], axis=2)  # (F, K) metres, NaN where unseen
    together = np.isfinite(D)
    if not together.any():
        return CandidateScore(index, int(seen.sum()), int(seen.sum()), None)
    med = np.array([np.median(D[together[:, k], k]) if together[:, k].any() else np.nan for k in range(D.shape[1])])
    dev = np.abs(D - med)
    off = np.any(together & (dev > RIGID_TOLERANCE), axis=1)
    return CandidateScore(index, int(seen.sum()), int((seen & ~off).sum()), float(np.median(dev[together])))


def _partners(rec: MarkerRecording, ms: MarkerSet, role: str) -> list[int]:
    """The markers of ``role``'s segment other than the role's candidates."""
    from .functional import SEGMENT_ROLES, segment_markers

    segment = next(seg for seg, roles in SEGMENT_ROLES.items() if role in roles)
    claimants = set(ms.candidates[role])
    return sorted(j for j, seg in segment_markers(rec, ms).items() if seg == segment and j not in claimants)


def choose_candidates(rec: MarkerRecording, ms: MarkerSet) -> MarkerSet:
    """``ms`` with each role of :attr:`~.markerset.MarkerSet.candidates` given to its best
    candidate (module docstring), the reason in :attr:`~.markerset.MarkerSet.choices`, and
    one warning naming the file, every such role, the marker used and the figures."""
    if not ms.candidates:
        return ms
    roles, choices = dict(ms.roles), dict(ms.choices)
    F = rec.num_frames
    for role, cands in sorted(ms.candidates.items()):
        partners = _partners(rec, ms, role)
        scores = sorted((score_candidate(rec, i, partners) for i in cands), key=CandidateScore.key)
        roles[role] = scores[0].index
        against = ", ".join(rec.labels[j] for j in partners) or "no other marker"
        choices[role] = (f"{' and '.join(rec.labels[i] for i in cands)} are all read as {role}; "
                         f"{rec.labels[scores[0].index]} is used, rigid with {against} in the most frames: "
                         + "; ".join(s.describe(rec.labels, F) for s in scores))
    warn(f"{rec.source}: " + " | ".join(choices[r] for r in sorted(ms.candidates))
         + ". A marker set file (--marker-set) that names the role chooses otherwise")
    return replace(ms, roles=roles, unused=unused_labels(rec.labels, roles), choices=choices, candidates={})
