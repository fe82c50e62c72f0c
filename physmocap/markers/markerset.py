"""Marker sets: which marker label plays which anatomical role.

A *role* is a landmark the joint-centre regressions use (:mod:`.joints`): pelvis
``LASI RASI LPSI RPSI SACR``, head ``LFHD RFHD LBHD RBHD``, trunk ``C7 T10 CLAV STRN``,
per side (``L``/``R`` prefix) ``SHO ELB ELBM WRA WRB FIN THI KNE KNEM TIB ANK ANKM HEE TOE``
(``M`` = medial).  Built-in aliases cover the names of the common protocols: Vicon Plug-in
Gait (full and lower body), the CMU 41-marker set (``LFWT`` for ``LASI``...), Helen Hayes /
Davis (``SACR``, ``LTIB``), Qualisys sports/animation (``L_IAS``, ``L_HLE``, ``L_FAL``...) and
OptiTrack Motive Baseline (``WaistLFront``, ``LKneeOut``...).  Labels are compared without
subject prefix, case or punctuation (:func:`~.recording.plain_label`).  A user TOML file
``[markers] ROLE = "label"`` overrides or adds entries; markers that play no role (props,
cluster markers) are listed as unused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from ..errors import InputError, MappingError
from ..fileio import read_toml
from .recording import plain_label

__all__ = ["ROLES", "ALIASES", "MarkerSet", "detect_marker_set", "load_marker_set", "recording_marker_set",
           "unused_labels"]

_SIDED = ("SHO", "ELB", "ELBM", "WRA", "WRB", "FIN", "THI", "KNE", "KNEM", "TIB", "ANK", "ANKM", "HEE", "TOE")
#: Every role, in a stable order.
ROLES: tuple[str, ...] = (
    ("LASI", "RASI", "LPSI", "RPSI", "SACR", "LFHD", "RFHD", "LBHD", "RBHD", "C7", "T10", "CLAV", "STRN")
    + tuple(f"{s}{r}" for s in "LR" for r in _SIDED)
)

_SIDED_ALIASES: dict[str, tuple[str, ...]] = {
    # role: aliases with {s} for the side letter (L/R) and {side} for Left/Right
    "SHO": ("{s}SHO", "{s}SHOULDER", "{s}SAE", "{s}ACR", "{side}SHOULDERTOP", "{s}SHOULDERTOP", "{s}ACROMION"),
    "ELB": ("{s}ELB", "{s}ELBOW", "{s}HLE", "{s}ELBOWOUT", "{side}ELBOWOUT", "{s}LEL", "{s}ELBL"),
    "ELBM": ("{s}ELBM", "{s}HME", "{s}MEL", "{s}ELBOWIN", "{side}ELBOWIN", "{s}ELBMED"),
    "WRA": ("{s}WRA", "{s}RSP", "{s}WRISTOUT", "{side}WRISTOUT", "{s}WRR", "{s}RAD"),
    "WRB": ("{s}WRB", "{s}USP", "{s}WRISTIN", "{side}WRISTIN", "{s}WRU", "{s}ULN"),
    "FIN": ("{s}FIN", "{s}HM2", "{s}HANDOUT", "{side}HANDOUT", "{s}MCP2", "{s}FINGER"),
    "THI": ("{s}THI", "{s}THIGH", "{side}THIGH", "{s}TH"),
    "KNE": ("{s}KNE", "{s}KNEE", "{s}FLE", "{s}KNEEOUT", "{side}KNEEOUT", "{s}LKN", "{s}KNEL"),
    "KNEM": ("{s}KNEM", "{s}FME", "{s}KNEEIN", "{side}KNEEIN", "{s}MKN", "{s}KNEMED"),
    "TIB": ("{s}TIB", "{s}SHN", "{s}SHIN", "{side}SHIN", "{s}TT"),
    "ANK": ("{s}ANK", "{s}ANKLE", "{s}FAL", "{s}LMAL", "{s}ANKLEOUT", "{side}ANKLEOUT", "{s}ANKL"),
    "ANKM": ("{s}ANKM", "{s}TAM", "{s}MMAL", "{s}ANKLEIN", "{side}ANKLEIN", "{s}MED"),
    "HEE": ("{s}HEE", "{s}HEEL", "{s}FCC", "{side}HEEL", "{s}CAL"),
    "TOE": ("{s}TOE", "{s}FM2", "{s}TOEIN", "{side}TOEIN", "{s}TOETIP", "{s}MT2", "{s}FOOT"),
}
_PLAIN_ALIASES: dict[str, tuple[str, ...]] = {
    "LASI": ("LASI", "LFWT", "LIAS", "WAISTLFRONT", "LASIS", "LEFTASIS", "ASISL", "ASISLEFT"),
    "RASI": ("RASI", "RFWT", "RIAS", "WAISTRFRONT", "RASIS", "RIGHTASIS", "ASISR", "ASISRIGHT"),
    "LPSI": ("LPSI", "LBWT", "LIPS", "WAISTLBACK", "LPSIS", "PSISL"),
    "RPSI": ("RPSI", "RBWT", "RIPS", "WAISTRBACK", "RPSIS", "PSISR"),
    "SACR": ("SACR", "SACRUM", "SACRAL", "MPSIS", "SAC"),
    "LFHD": ("LFHD", "LFH", "HEADLFRONT", "LHEADFRONT"),
    "RFHD": ("RFHD", "RFH", "HEADRFRONT", "RHEADFRONT"),
    "LBHD": ("LBHD", "LBH", "HEADLBACK", "LHEADBACK"),
    "RBHD": ("RBHD", "RBH", "HEADRBACK", "RHEADBACK"),
    "C7": ("C7", "CV7", "BACKTOP", "C7SPINE", "T1"),
    "T10": ("T10", "TV10", "TH10", "BACKMIDDLE"),
    "CLAV": ("CLAV", "SJN", "IJ", "CHESTTOP", "JUGULAR", "STER", "MAN", "MANUBRIUM"),
    "STRN": ("STRN", "SXS", "PX", "CHEST", "STERNUM", "XIPHOID", "XIPH"),
}


def _aliases() -> dict[str, str]:
    """Normalised label -> role."""
    out: dict[str, str] = {}
    for role, names in _PLAIN_ALIASES.items():
        for n in names:
            out[n] = role
    for s, side in (("L", "LEFT"), ("R", "RIGHT")):
        for role, names in _SIDED_ALIASES.items():
            for n in names:
                out.setdefault(n.format(s=s, side=side), f"{s}{role}")
    return out


#: Normalised marker label -> role.
ALIASES: dict[str, str] = _aliases()


@dataclass(frozen=True)
class MarkerSet:
    """Roles found in one recording.

    Attributes:
        roles: Role -> index of the marker playing it.
        unused: Labels that play no role (props, clusters, extra markers).
        origin: ``"aliases"`` or the TOML file used.
        candidates: Role -> indices of every marker whose label the aliases read as that role,
            for the roles that two or more different labels claim (``LKNE`` and ``LFLE``) and
            no marker set file assigns; until :func:`.candidates.choose_candidates` picks one
            from the data, the first in the file holds the role.
        choices: Role -> why its marker was chosen among its candidates (one sentence).
    """

    roles: dict[str, int]
    unused: tuple[str, ...]
    origin: str = "aliases"
    candidates: dict[str, tuple[int, ...]] = field(default_factory=dict)
    choices: dict[str, str] = field(default_factory=dict)

    def has(self, *roles: str) -> bool:
        return all(r in self.roles for r in roles)


def unused_labels(labels: tuple[str, ...] | list[str], roles: dict[str, int]) -> tuple[str, ...]:
    """The labels of the markers that play none of ``roles`` (role -> marker index), in file order."""
    used = set(roles.values())
    return tuple(lab for i, lab in enumerate(labels) if i not in used)


def detect_marker_set(labels: tuple[str, ...] | list[str], overrides: dict[str, str] | None = None) -> MarkerSet:
    """Roles of ``labels`` by the built-in aliases, then ``overrides`` (role -> label).

    Labels alone cannot say which of two different labels read as one role is the better
    marker: such a role keeps them all in :attr:`MarkerSet.candidates` (the first holds it
    meanwhile) for :func:`.candidates.choose_candidates` to decide from the recording, unless
    ``overrides`` assigns the role.  A marker the file gives another role is no candidate."""
    claims: dict[str, list[int]] = {}
    for i, lab in enumerate(labels):
        role = ALIASES.get(plain_label(lab))
        if role is not None and all(plain_label(labels[k]) != plain_label(lab) for k in claims.get(role, [])):
            claims.setdefault(role, []).append(i)
    given = _file_roles(labels, overrides or {})
    roles, candidates = dict(given), {}
    for role, idx in claims.items():
        free = tuple(i for i in idx if i not in given.values())
        if role in given or not free:
            continue
        roles[role] = free[0]
        if len(free) > 1:
            candidates[role] = free
    origin = "aliases + file" if overrides else "aliases"
    return MarkerSet(roles=roles, unused=unused_labels(labels, roles), origin=origin, candidates=candidates)


def _file_roles(labels: tuple[str, ...] | list[str], overrides: dict[str, str]) -> dict[str, int]:
    """Role -> marker index of a marker set file's ``overrides`` (role -> label).

    Raises:
        MappingError: An unknown role, or a label not in the recording.
    """
    plain = {plain_label(lab): i for i, lab in enumerate(labels)}
    out = {}
    for role, lab in overrides.items():
        if role not in ROLES:
            raise MappingError(f"unknown marker role {role!r}; roles are {' '.join(ROLES)}")
        i = plain.get(plain_label(lab))
        if i is None:
            raise MappingError(f"marker {lab!r} (for {role}) is not in the recording; its labels are {', '.join(labels)}")
        out[role] = i
    return out


def recording_marker_set(rec, marker_set: "str | os.PathLike | MarkerSet | None" = None) -> MarkerSet:
    """The roles of a recording's markers: the aliases, the user's TOML file ``marker_set``
    (or a ready :class:`MarkerSet`), a choice from the data where two labels claim one role
    and the file does not say (:func:`.candidates.choose_candidates`), then single-limb
    markers placed on their side by where they are (:func:`.sides.with_sides`)."""
    from .candidates import choose_candidates
    from .sides import with_sides

    if isinstance(marker_set, MarkerSet):
        return marker_set
    if marker_set is None:
        return with_sides(rec, choose_candidates(rec, detect_marker_set(rec.labels)))
    try:
        ms = detect_marker_set(rec.labels, load_marker_set(marker_set))
    except MappingError as exc:  # a role or label of the user's file: name the file, and the recording
        raise MappingError(f"{exc.message} (recording {rec.source})", path=marker_set) from None
    return with_sides(rec, choose_candidates(rec, ms))


def load_marker_set(path: str | os.PathLike) -> dict[str, str]:
    """Role -> label from a TOML file ``[markers] LKNE = "Subject:L_Knee"``."""
    data, _ = read_toml(path, kind="marker set file")
    table = data.get("markers")
    if not isinstance(table, dict) or not all(isinstance(v, str) for v in table.values()):
        raise InputError('a marker set file needs a [markers] table of ROLE = "label" strings', path=path)
    return {str(k).upper(): v for k, v in table.items()}


def marker_set_toml(labels: tuple[str, ...] | list[str], ms: MarkerSet) -> str:
    """A marker set file to edit: every role with the label playing it (or commented out)."""
    lines = ["# physmocap marker set: ROLE = \"label as in the file\"; delete or fix the guesses", "[markers]"]
    for role in ROLES:
        if role in ms.choices:
            lines.append(f"# {role}: {ms.choices[role]}")
        if role in ms.roles:
            lines.append(f'{role} = "{labels[ms.roles[role]]}"')
        else:
            lines.append(f'# {role} = ""')
    if ms.unused:
        lines.append("# markers that play no role: " + ", ".join(ms.unused))
    return "\n".join(lines) + "\n"
