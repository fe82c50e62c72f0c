"""Which side of the body a marker is on, from where it is (for labels that do not say).

Single-limb protocols name markers without a side (the ISB-style upper-limb set of
``vicon_upperbody*``: ``ACRO_tip``, ``EPICl``/``EPICm`` lateral/medial epicondyle,
``STYLr``/``STYLu`` radial/ulnar styloid, ``INDEX``), and a trailing lowercase letter there
means lateral, medial, radial or ulnar, not left or right.  Such a marker's side is the sign
of its median distance from the body's midline along the left axis (per frame: from the
right to the left ASIS, else acromion, else front head marker), when that distance is at
least :data:`MIN_LATERAL` (metres).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .markerset import MarkerSet, unused_labels
from .recording import MarkerRecording, plain_label

__all__ = ["SIDELESS_ROLES", "lateral_offsets", "side_of", "with_sides"]

#: Plain labels of single-limb markers -> the sided role they play (side from geometry).
SIDELESS_ROLES: dict[str, str] = {
    "ACROTIP": "SHO", "ACROMION": "SHO", "ACRO": "SHO",
    "EPICL": "ELB", "EPICM": "ELBM", "ELBL": "ELB", "ELBM": "ELBM",
    "STYLR": "WRA", "STYLU": "WRB",
    "INDEX": "FIN",
}
#: Smallest distance (metres, median over the clip) from the midline for a marker to have a
#: side.  An engineering choice, not from a paper: it must separate the midline markers, whose
#: placement and skin motion leave them a few centimetres off the line (sternum, clavicular
#: notch, C7, a head marker seen from a tilted pelvis axis), from the limb markers, which sit
#: at least a hip or shoulder half-width off it (the ASIS half-width alone is about 12 cm:
#: :mod:`.joints` takes 0.25 m ASIS to ASIS for an adult); 5 cm is well inside that gap.
MIN_LATERAL = 0.05


def lateral_offsets(rec: MarkerRecording, ms: MarkerSet) -> np.ndarray | None:
    """``(M,)`` median signed distance (metres, + left) of every marker from the midline, or
    None when no left/right marker pair gives the body's left axis."""
    P = rec.positions
    for a, b in (("LASI", "RASI"), ("LSHO", "RSHO"), ("LFHD", "RFHD")):
        if a in ms.roles and b in ms.roles:
            L, R = P[:, ms.roles[a]], P[:, ms.roles[b]]
            break
    else:
        return None
    y = L - R
    n = np.linalg.norm(y, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        y = y / n
        d = np.einsum("fmk,fk->fm", P - (0.5 * (L + R))[:, None], y)
    ok = np.isfinite(d)
    out = np.full(P.shape[1], np.nan)
    for i in range(P.shape[1]):
        if ok[:, i].any():
            out[i] = float(np.median(d[ok[:, i], i]))
    return out


def side_of(offset: float) -> str | None:
    """``"left"``, ``"right"`` or None (too near the midline, or unknown)."""
    if not np.isfinite(offset) or abs(offset) < MIN_LATERAL:
        return None
    return "left" if offset > 0 else "right"


def with_sides(rec: MarkerRecording, ms: MarkerSet) -> MarkerSet:
    """``ms`` with the unused single-limb markers (:data:`SIDELESS_ROLES`) given their role on
    the side where they are, unless a marker already plays it."""
    candidates = [i for i, lab in enumerate(rec.labels) if lab in ms.unused and plain_label(lab) in SIDELESS_ROLES]
    if not candidates:
        return ms
    off = lateral_offsets(rec, ms)
    if off is None:
        return ms
    roles = dict(ms.roles)
    for i in candidates:
        side = side_of(off[i])
        role = f"{'L' if side == 'left' else 'R'}{SIDELESS_ROLES[plain_label(rec.labels[i])]}" if side else None
        if role is not None and role not in roles:
            roles[role] = i
    return replace(ms, roles=roles, unused=unused_labels(rec.labels, roles), origin=ms.origin + " + sides from positions")
