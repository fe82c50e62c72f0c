r"""Joint centres from labelled markers, then a positional motion of canonical joints.

Per frame, from the roles of :mod:`.markerset` (all metres; a joint is NaN on a frame
where a marker it needs is invalid):

* **Hips** (Harrington et al. 2007, J. Biomech. 40:595, the regression Vicon and
  Visual3D recommend): in the pelvis frame (origin mid-ASIS, :math:`y` to the left ASIS,
  :math:`x` anterior, from mid-PSIS or the sacrum to mid-ASIS, :math:`z` up) with pelvis
  width :math:`W` (ASIS to ASIS) and depth :math:`D` (mid-ASIS to mid-PSIS), each hip is
  at :math:`x = -0.24 D - 9.9\,mm`, :math:`z = -0.30 W - 10.9\,mm`,
  :math:`y = \pm(0.33 W + 7.3\,mm)`.
* **Knees, ankles, elbows**: the midpoint of the lateral and medial markers where both
  exist; else the lateral marker moved medially by a joint half-width, perpendicular to
  the proximal segment, towards the body's midline.  Half-widths scale with the pelvis
  width (or the shoulder width for elbows): knee :math:`0.20 W`, ankle :math:`0.14 W`,
  elbow :math:`0.11 S` (about 50, 35 and 40 mm on an adult; Plug-in Gait asks for the
  measured widths, which a marker file does not carry), plus the marker's radius as in
  Plug-in Gait's offset :math:`(\text{width} + \text{marker diameter}) / 2` (the marker's
  centre sits a radius off the skin; :data:`MARKER_DIAMETER`, Vicon's standard 14 mm).
* **Shoulders** (Rab et al. 2002, Gait Posture 15:113): the glenohumeral centre lies
  :math:`0.17 S` below the acromion marker (:math:`S` the distance between the two acromion
  markers) along the thorax's long axis (from mid T10-sternum to mid C7-clavicle, else the
  lab's up axis), whatever the arm does.
* **Wrists**: midpoint of the two wrist markers; **hand end**: the finger marker.
* **Neck**: midpoint of C7 and the clavicle (jugular notch) marker; **chest**: midpoint of
  T10 and the sternum marker; **head**: centroid of the head markers.
* **Toes**: the toe (second metatarsal) marker.

This is the anatomical-regression half of issue 11's calibration; :mod:`.functional` uses the
motion where it can place a centre and keeps these elsewhere.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, warn
from .markerset import MarkerSet
from .recording import MarkerRecording
from ..vectors import unit

__all__ = ["JointCentres", "joint_centres", "up_axis", "MARKER_DIAMETER"]

#: Diameter (metres) of the markers: their centre sits a radius off the skin (Plug-in Gait's
#: joint offsets add it to the joint width).  Vicon's standard full-body marker is 14 mm.
MARKER_DIAMETER = 0.014


@dataclass(frozen=True)
class JointCentres:
    """Canonical joint -> ``(F, 3)`` centres (metres, the file's axes), and how each was found."""

    positions: dict[str, np.ndarray]
    method: dict[str, str]


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` normalised along its last axis; NaN where it is shorter than 1e-9 (or NaN)."""
    u, n = unit(v)
    return np.where(n[..., None] > 1e-9, u, np.nan)


def _perp(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Component of ``v`` perpendicular to unit ``axis`` (both ``(F, 3)``)."""
    return v - np.sum(v * axis, axis=-1, keepdims=True) * axis


def _scalar(x: np.ndarray, fallback: float) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else fallback


def up_axis(rec: MarkerRecording, ms: MarkerSet) -> np.ndarray:
    """Unit vector (one of the file's signed axes) pointing up: from the feet or pelvis
    markers to the head or trunk markers, median over the clip; Z when undecidable."""
    P = rec.positions

    def centroid(roles: tuple[str, ...]) -> np.ndarray | None:
        idx = [ms.roles[r] for r in roles if r in ms.roles]
        if not idx:
            return None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames where none of them is seen: NaN
            return np.nanmean(P[:, idx], axis=1)

    top = centroid(("LFHD", "RFHD", "LBHD", "RBHD", "C7", "CLAV"))
    low = centroid(("LANK", "RANK", "LHEE", "RHEE", "LTOE", "RTOE"))
    if low is None:
        low = centroid(("LASI", "RASI", "LPSI", "RPSI", "SACR", "T10", "STRN"))
    if top is None or low is None:
        return np.array([0.0, 0.0, 1.0])
    with np.errstate(invalid="ignore"):
        d = np.nanmedian(top - low, axis=0)
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-6:
        return np.array([0.0, 0.0, 1.0])
    k = int(np.argmax(np.abs(d)))
    out = np.zeros(3)
    out[k] = np.sign(d[k])
    return out


def joint_centres(rec: MarkerRecording, ms: MarkerSet) -> JointCentres:
    """Canonical joint centres of one recording (see the module docstring)."""
    P = rec.positions
    up = up_axis(rec, ms)
    F = rec.num_frames

    def m(role: str) -> np.ndarray | None:
        return P[:, ms.roles[role]] if role in ms.roles else None

    out: dict[str, np.ndarray] = {}
    how: dict[str, str] = {}
    W = S = np.nan
    # --- pelvis and hips
    lasi, rasi = m("LASI"), m("RASI")
    back = None
    if m("LPSI") is not None and m("RPSI") is not None:
        back = 0.5 * (m("LPSI") + m("RPSI"))
    elif m("SACR") is not None:
        back = m("SACR")
    elif m("LPSI") is not None or m("RPSI") is not None:
        back = m("LPSI") if m("LPSI") is not None else m("RPSI")
    if lasi is not None and rasi is not None and back is not None:
        mid = 0.5 * (lasi + rasi)
        y = _unit(lasi - rasi)
        x = _unit(_perp(mid - back, y))
        z = np.cross(x, y)
        W = _scalar(np.linalg.norm(lasi - rasi, axis=-1), np.nan)
        D = np.linalg.norm(_perp(mid - back, y), axis=-1)
        for side, sign in (("left", 1.0), ("right", -1.0)):
            hx = -0.24 * D - 0.0099
            hz = -0.30 * W - 0.0109
            hy = sign * (0.33 * W + 0.0073)
            out[f"{side}_hip"] = mid + hx[:, None] * x + hy * y + hz * z
            how[f"{side}_hip"] = "Harrington 2007 regression"
    if not np.isfinite(W):
        W = 0.25  # an adult's inter-ASIS width, for the half-widths below
    shoulders = [m("LSHO"), m("RSHO")]
    if shoulders[0] is not None and shoulders[1] is not None:
        S = _scalar(np.linalg.norm(shoulders[0] - shoulders[1], axis=-1), 0.38)
    else:
        S = 0.38
    mid_hip = 0.5 * (out["left_hip"] + out["right_hip"]) if "left_hip" in out else None
    trunk = None
    if m("CLAV") is not None and m("C7") is not None:
        trunk = 0.5 * (m("CLAV") + m("C7"))
        out["neck"] = trunk
        how["neck"] = "midpoint of C7 and CLAV"
    thorax_up = np.broadcast_to(up, P[:, 0].shape)
    if m("T10") is not None and m("STRN") is not None:
        out["chest"] = 0.5 * (m("T10") + m("STRN"))
        how["chest"] = "midpoint of T10 and STRN"
        if trunk is not None:  # ISB thorax long axis; the lab's up where a marker is missing
            axis = _unit(trunk - out["chest"])
            thorax_up = np.where(np.isfinite(axis), axis, up)
    head = [m(r) for r in ("LFHD", "RFHD", "LBHD", "RBHD") if m(r) is not None]
    if len(head) >= 2:
        out["head"] = np.mean(head, axis=0)
        how["head"] = f"centroid of {len(head)} head markers"

    def medial_joint(name: str, lateral: str, medial: str, proximal: np.ndarray | None, half: float, midline) -> None:
        lat, med = m(lateral), m(medial)
        if lat is None:
            return
        if med is not None:
            out[name] = 0.5 * (lat + med)
            how[name] = f"midpoint of {lateral} and {medial}"
            return
        if proximal is None or midline is None:
            return
        axis = _unit(lat - proximal)
        inward = _unit(_perp(midline - lat, axis))
        out[name] = lat + half * inward
        how[name] = f"{lateral} moved {1000 * half:.0f} mm medially"

    for s, side in (("L", "left"), ("R", "right")):
        hip = out.get(f"{side}_hip")
        r = MARKER_DIAMETER / 2
        medial_joint(f"{side}_knee", f"{s}KNE", f"{s}KNEM", hip, 0.20 * W + r, mid_hip)
        medial_joint(f"{side}_ankle", f"{s}ANK", f"{s}ANKM", out.get(f"{side}_knee"), 0.14 * W + r, mid_hip)
        if m(f"{s}TOE") is not None:
            out[f"{side}_toe"] = m(f"{s}TOE")
            how[f"{side}_toe"] = f"{s}TOE"
        sho = m(f"{s}SHO")
        if sho is not None:
            out[f"{side}_shoulder"] = sho - 0.17 * S * thorax_up
            how[f"{side}_shoulder"] = f"{s}SHO moved {170 * S:.0f} mm down the thorax (Rab 2002)"
        medial_joint(f"{side}_elbow", f"{s}ELB", f"{s}ELBM", out.get(f"{side}_shoulder"), 0.11 * S + r, trunk)
        wra, wrb = m(f"{s}WRA"), m(f"{s}WRB")
        if wra is not None and wrb is not None:
            out[f"{side}_wrist"] = 0.5 * (wra + wrb)
            how[f"{side}_wrist"] = f"midpoint of {s}WRA and {s}WRB"
        elif wra is not None or wrb is not None:
            out[f"{side}_wrist"] = wra if wra is not None else wrb
            how[f"{side}_wrist"] = "one wrist marker"
        if m(f"{s}FIN") is not None:
            out[f"{side}_hand_end"] = m(f"{s}FIN")
            how[f"{side}_hand_end"] = f"{s}FIN"
    if not out:
        raise InputError(
            "no joint centre can be computed: the marker labels match no known marker set "
            f"(labels: {', '.join(rec.labels[:20])}{' ...' if len(rec.labels) > 20 else ''}); "
            "give a marker set file with --marker-set",
            path=rec.source,
        )
    del F
    return JointCentres(positions=out, method=how)


def warn_unused(rec: MarkerRecording, ms: MarkerSet) -> None:
    """One warning naming the markers that play no role (ignored)."""
    if ms.unused:
        shown = ", ".join(ms.unused[:12]) + (" ..." if len(ms.unused) > 12 else "")
        warn(f"{rec.source}: {len(ms.unused)} marker(s) play no role in the skeleton and are ignored: {shown}")
