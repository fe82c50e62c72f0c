"""Propose a mapping file for a humanoid MJCF from its body names and kinematic tree.

``physmocap character init ROBOT.xml`` calls :func:`propose_mapping`, which works on
the compiled model in its rest pose (a keyframe named for a standing pose, ``rest``,
``home``, ``stand`` or ``standing``, if the model has one (:func:`rest_keyframe`), else
the zero pose):

1. **Root**: the body of the free joint.  Up is against gravity (``opt.gravity``).
2. **Legs**: descending from the root, the first body with two child branches that
   both reach the lowest body origins is the pelvis; each branch, followed down to its
   lowest leaf, is a leg.
3. **Arms**: among the branches left (not legs, not above the pelvis's path to the
   root), the pair of chains on opposite sides with the longest similar reach.  A robot
   with no such pair (a legs-only biped), or an arm whose shoulder or elbow cannot be told,
   gets no arm on that side: it is left out with a note ("no arms: the arms of the actor
   are not tracked"), and the loader takes the character without it
   (:data:`~physmocap.models.character.OPTIONAL_LIMBS`).
4. **Sides** from name tokens (``left_``, ``l_``, ``L_``, ``_l``, ``Left``...) of the
   chain's bodies and joints; when the names do not tell, from the lateral position in
   the rest pose (MuJoCo's convention: a model faces +X, its left is +Y).
5. **Parts** along each chain by name keywords (hip, thigh, knee, calf, shin, shank,
   ankle, foot, toe, shoulder, upper_arm, elbow, forearm, wrist, hand...), else by chain
   position (hip first, knee at mid-height, ankle the last articulation point above the
   sole, or one the leg reaches going more down than forward: a toe lies along the foot).  Among the
   bodies of one part (a 3-DOF hip is often three bodies), a joint centre takes the body
   nearest the point closest to the part's joint axes (ties: the earlier body); the ankle
   takes the last articulated body, whose frame turns with every DOF of the foot (the sole
   must lie flat); a hip told by position is the body nearest the meeting point of the
   hinge axes before the knee.  The wrist is a joint centre: the hand's end, when the model has one,
   steers the wrist's last DOF (tracking the whole hand frame swung the G1's wrist roll
   to 66 degrees on the PyMO walk, against 35 this way).
   A hand body fixed at the forearm's end is the wrist.  A foot without a toe body gets a
   ball-of-foot site on its ankle body (``[sites]``; foot planting needs a toe point).
   Geometry checks the names: a hip whose bodies are not over the knee in the rest pose (the
   yaw and roll bodies inward of an offset pitch body) takes the body over the knee; an elbow
   whose hinges only turn the arm about its length gives way to the first hinge beyond that
   bends it; the shoulder is the body nearest the meeting point of the hinges before the
   elbow where the named one is further; an arm with no wrist joint gets a wrist site at the
   end of its forearm's geoms.  A keyword on every articulated body of a limb (Atlas's
   ``l_leg_*`` joints) names the limb and tells no part.
6. **Trunk**: articulation points on the tree path between the pelvis and the arms'
   branching body are spine (then chest); a head branch with joints gives neck and head
   (one such body is the head).  A robot whose head has no joint gets no neck, head or head
   end (the loader treats the neck as optional).  Without arms the trunk runs up to the
   highest body outside the legs; from the first body on it named neck or head, it is the
   head's (without such a name, all of it is trunk: nothing else tells a chest from a head).
7. **Rest pose**: with no keyframe, a joint whose zero is outside its range takes the
   nearest end, and an elbow or knee that the zero pose bends by more than 20 degrees is
   straightened (``[rest.joints]``).

Nothing here is specific to a robot.  Joints the model does not have are left out and
reported.  Errors (:class:`~physmocap.errors.InputError`,
:class:`~physmocap.errors.MappingError`) name the file.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from ..canonical import CANONICAL_NAMES
from ..errors import MappingError

__all__ = ["Guess", "Proposal", "propose_mapping", "name_side", "name_parts", "rest_keyframe", "REST_KEY_WORDS"]

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)

# -- names -----------------------------------------------------------------------------

_LEFT = {"left", "l", "lft", "lt"}
_RIGHT = {"right", "r", "rgt", "rt"}

#: Keyword -> part.  A body named like a segment is the segment's proximal joint
#: (a thigh's origin is the hip, a calf's the knee, a forearm's the elbow).
_LEG_WORDS = {
    "hip": "hip", "thigh": "hip", "femur": "hip", "upleg": "hip", "upperleg": "hip",
    "knee": "knee", "calf": "knee", "shin": "knee", "shank": "knee", "tibia": "knee",
    "lowerleg": "knee", "leg": "knee", "uleg": "hip", "lleg": "knee",
    "ankle": "ankle", "foot": "ankle", "talus": "ankle",
    "toe": "toe", "toes": "toe", "toebase": "toe", "ball": "toe",
}
_ARM_WORDS = {
    "clavicle": "clavicle", "collar": "clavicle", "scapula": "clavicle",
    "shoulder": "shoulder", "upperarm": "shoulder", "humerus": "shoulder", "arm": "shoulder", "uarm": "shoulder",
    "shld": "shoulder", "elb": "elbow", "larm": "elbow",
    "elbow": "elbow", "forearm": "elbow", "lowerarm": "elbow", "radius": "elbow", "ulna": "elbow",
    "wrist": "wrist", "hand": "hand", "palm": "hand",
}
_HEAD_WORDS = {"neck": "neck", "cervical": "neck", "head": "head", "skull": "head"}
_ALL_WORDS = {**_LEG_WORDS, **_ARM_WORDS, **_HEAD_WORDS}
_BIGRAMS = {
    ("up", "leg"): "upleg", ("upper", "leg"): "upperleg", ("lower", "leg"): "lowerleg",
    ("upper", "arm"): "upperarm", ("lower", "arm"): "lowerarm", ("fore", "arm"): "forearm",
    ("toe", "base"): "toebase",
}


def _tokens(name: str) -> list[str]:
    """``LeftUpLeg`` -> left, up, leg; ``l_calf_link`` -> l, calf, link; ``L_KNEE`` -> l, knee."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", " ", name)
    raw = [t.lower() for t in re.split(r"[^A-Za-z]+|\s+", spaced) if t]
    out: list[str] = []
    i = 0
    while i < len(raw):
        if i + 1 < len(raw) and (raw[i], raw[i + 1]) in _BIGRAMS:
            out.append(_BIGRAMS[(raw[i], raw[i + 1])])
            i += 2
            continue
        t = raw[i]
        # "lfemur", "rknee": a one-letter side glued to a keyword
        if t not in _ALL_WORDS and len(t) > 2 and t[0] in "lr" and t[1:] in _ALL_WORDS:
            out += [t[0], t[1:]]
        else:
            out.append(t)
        i += 1
    return out


def name_side(name: str) -> str | None:
    """``"left"``, ``"right"`` or None, from a name's tokens."""
    toks = set(_tokens(name))
    left, right = bool(toks & _LEFT), bool(toks & _RIGHT)
    if left != right:
        return "left" if left else "right"
    return None


def name_parts(name: str, words: dict[str, str]) -> list[str]:
    """Parts (``hip``, ``knee``...) a name's tokens mention, in order, for one vocabulary."""
    return [words[t] for t in _tokens(name) if t in words]


# -- the proposal ------------------------------------------------------------------------


@dataclass
class Guess:
    """One canonical joint's proposed frame and the reason for it."""

    canonical: str
    kind: str  # "body" or "site"
    name: str
    why: str


@dataclass
class Proposal:
    """A proposed mapping for one MJCF (see the module docstring)."""

    mjcf: Path
    name: str
    up: str
    forward: str
    joints: dict[str, Guess]
    left_out: dict[str, str]
    rest_keyframe: str | None
    rest_joints: dict[str, float]
    rest_note: str
    notes: list[str] = field(default_factory=list)
    sites: dict[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)  # name -> (body, pos)

    def to_toml(self) -> str:
        """The mapping file's text."""
        lines = [
            f"# Mapping proposed by `physmocap character init` for {self.mjcf.name}.",
            "# Check it with `physmocap character info MODEL.xml --map THIS.map.toml`; edit as needed.",
            "# Foot contacts: none listed, so the heel and toe are found on the feet's collision geoms.",
            "",
            "[character]",
            f"name = {_q(self.name)}",
            f"up = {_q(self.up)}",
            f"forward = {_q(self.forward)}",
            "",
        ]
        if self.sites:
            lines += ["[sites]                       # points the model lacks, added before it is compiled"]
            for sn, (body, pos) in self.sites.items():
                xyz = ", ".join(f"{v:.4f}" for v in pos)
                lines.append(f"{_key(sn)} = {{ body = {_q(body)}, pos = [{xyz}] }}")
            lines.append("")
        lines.append("[joints]")
        width = max((len(c) for c in self.joints), default=0)
        for canon in CANONICAL_NAMES:
            g = self.joints.get(canon)
            if g is not None:
                value = _q(f"{g.kind}:{g.name}")
                lines.append(f"{canon:<{width}} = {value:<34} # {g.why}")
        if self.left_out:
            lines.append("# left out (the model has no such joint): " + ", ".join(self.left_out))
        lines += ["", f"# rest pose: {self.rest_note}"]
        if self.rest_keyframe is not None:
            lines += ["[rest]", f"keyframe = {_q(self.rest_keyframe)}"]
        if self.rest_joints:
            lines.append("[rest.joints]                 # degrees (hinges), metres (slides)")
            for jn, deg in self.rest_joints.items():
                lines.append(f"{_key(jn)} = {deg:.6g}")
        return "\n".join(lines) + "\n"

    def report(self) -> list[str]:
        """What was guessed, one line each (for stderr)."""
        out = [f"{self.mjcf}: proposed mapping for {self.name!r} (up {self.up}, forward {self.forward})"]
        for canon in CANONICAL_NAMES:
            g = self.joints.get(canon)
            if g is not None:
                out.append(f"  {canon:<15} -> {g.kind}:{g.name}  ({g.why})")
        if self.left_out:
            out.append("  left out: " + "; ".join(f"{c} ({why})" for c, why in self.left_out.items()))
        out.append(f"  rest pose: {self.rest_note}")
        out += [f"  note: {n}" for n in self.notes]
        return out


def _q(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _key(s: str) -> str:
    return s if re.fullmatch(r"[A-Za-z0-9_-]+", s) else _q(s)


# -- the model ---------------------------------------------------------------------------


class _Tree:
    """Bodies, their children and rest-pose geometry of a compiled model."""

    def __init__(self, model: mujoco.MjModel, qpos: np.ndarray):
        self.m = model
        self.children: dict[int, list[int]] = {b: [] for b in range(model.nbody)}
        for b in range(1, model.nbody):
            self.children[int(model.body_parentid[b])].append(b)
        d = mujoco.MjData(model)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(model, d)
        self.data = d
        self.xpos = d.xpos.copy()
        g = np.array(model.opt.gravity, dtype=float)
        self.up = _snap(-g) if np.linalg.norm(g) > 1e-9 else np.array([0.0, 0.0, 1.0])
        self.h = self.xpos @ self.up
        self._reach: dict[int, float] = {}
        self.lowest = {}
        for b in reversed(range(model.nbody)):  # children have larger ids than parents
            self.lowest[b] = min([self.h[b]] + [self.lowest[c] for c in self.children[b]])

    def name(self, b: int) -> str:
        return self.m.body(b).name

    def joints(self, b: int) -> list[int]:
        start, n = int(self.m.body_jntadr[b]), int(self.m.body_jntnum[b])
        return [j for j in range(start, start + n) if int(self.m.jnt_type[j]) != _FREE] if n > 0 else []

    def articulated(self, b: int) -> bool:
        return bool(self.joints(b))

    def names(self, b: int) -> list[str]:
        """The body's name and its joints' names."""
        return [self.name(b)] + [self.m.joint(j).name for j in self.joints(b)]

    def subtree(self, b: int) -> list[int]:
        out, stack = [], [b]
        while stack:
            x = stack.pop()
            out.append(x)
            stack += self.children[x]
        return out

    def reach(self, b: int) -> float:
        """Longest distance from ``b``'s origin to a descendant's origin."""
        if b not in self._reach:
            self._reach[b] = float(max(np.linalg.norm(self.xpos[x] - self.xpos[b]) for x in self.subtree(b)))
        return self._reach[b]

    def path_up(self, b: int, stop: int) -> list[int]:
        """``b``, its parent, ... up to and including ``stop`` (or the world)."""
        out = [b]
        while b != stop and b > 0:
            b = int(self.m.body_parentid[b])
            out.append(b)
        return out


def _snap(v: np.ndarray) -> np.ndarray:
    i = int(np.argmax(np.abs(v)))
    out = np.zeros(3)
    out[i] = math.copysign(1.0, float(v[i]))
    return out


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return ("-" if v[i] < 0 else "") + "XYZ"[i]


def _load(path: Path) -> mujoco.MjModel:
    from .character import read_mjcf

    return read_mjcf(path)


#: Words that name a standing keyframe, in order of preference (Menagerie's models use
#: ``home``; Apptronik Apollo's is ``stand``).
REST_KEY_WORDS = ("rest", "home", "stand", "standing")


def rest_keyframe(model: mujoco.MjModel) -> str | None:
    """The keyframe that is the model's standing pose: one named a word of
    :data:`REST_KEY_WORDS` (any case; the earlier word first), else the first whose name's
    tokens hold one (``stand_pose``, ``HomePose``); None if there is none."""
    names = [model.key(k).name for k in range(model.nkey)]
    for word in REST_KEY_WORDS:
        hit = next((n for n in names if n.lower() == word), None)
        if hit is not None:
            return hit
    for word in REST_KEY_WORDS:
        hit = next((n for n in names if word in _tokens(n)), None)
        if hit is not None:
            return hit
    return None


def _rest(model: mujoco.MjModel) -> tuple[np.ndarray, str | None]:
    key = rest_keyframe(model)
    if key is not None:
        return model.key_qpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, key)].copy(), key
    return model.qpos0.copy(), None


# -- chains --------------------------------------------------------------------------------


def _descend_lowest(t: _Tree, b: int) -> list[int]:
    chain = [b]
    while t.children[chain[-1]]:
        chain.append(min(t.children[chain[-1]], key=lambda c: t.lowest[c]))
    return chain


def _descend_longest(t: _Tree, b: int) -> list[int]:
    chain = [b]
    while t.children[chain[-1]]:
        x = chain[-1]
        chain.append(max(t.children[x], key=lambda c: float(np.linalg.norm(t.xpos[c] - t.xpos[b])) + t.reach(c)))
    return chain


def _find_legs(t: _Tree, root: int, path: Path) -> tuple[int, list[int], list[int]]:
    """The pelvis (where the legs branch) and the two leg chains."""
    low = t.lowest[root]
    span = t.h[root] - low
    if span <= 1e-3:
        raise MappingError("no recognisable legs: no body hangs below the free-joint body in the rest pose", path=path)
    tol = max(0.15 * span, 0.02)
    x = root
    while True:
        kids = [c for c in t.children[x] if t.lowest[c] <= low + tol]
        if len(kids) >= 2:
            kids.sort(key=lambda c: t.lowest[c])
            a, b = kids[0], kids[1]
            la, lb = _descend_lowest(t, a), _descend_lowest(t, b)
            if len(la) < 2 or len(lb) < 2:
                raise MappingError(
                    f"no recognisable legs: the branches below {t.name(x)!r} have fewer than two bodies each", path=path
                )
            return x, la, lb
        if len(kids) == 0:
            break
        x = kids[0]
    raise MappingError(
        "no recognisable legs: no body has two branches reaching down to the feet "
        f"(looked below {t.name(root)!r}, the free-joint body)",
        path=path,
    )


def _find_arms(t: _Tree, root: int, pelvis: int, legs: list[list[int]]):
    """The body the arms branch from and the two arm chains (or None)."""
    excluded = set()
    for leg in legs:
        excluded |= set(t.subtree(leg[0]))
    spine_path = set(t.path_up(pelvis, root))
    leg_len = sum(float(np.linalg.norm(t.xpos[leg[i + 1]] - t.xpos[leg[i]])) for leg in legs[:1] for i in range(len(leg) - 1))
    best = None
    for x in t.subtree(root):
        if x in excluded:
            continue
        kids = [c for c in t.children[x] if c not in excluded and c not in spine_path and c != pelvis]
        reach = {c: t.reach(c) + float(np.linalg.norm(t.xpos[c] - t.xpos[x])) for c in kids}
        for i, a in enumerate(kids):
            for b in kids[i + 1:]:
                ra, rb = reach[a], reach[b]
                if min(ra, rb) < 0.25 * leg_len or min(ra, rb) < 0.7 * max(ra, rb):
                    continue
                if len(t.subtree(a)) < 2 or len(t.subtree(b)) < 2:
                    continue
                # opposite sides: the two bases apart horizontally
                d = t.xpos[a] - t.xpos[b]
                d_h = d - (d @ t.up) * t.up
                if np.linalg.norm(d_h) < 0.04 or abs(d @ t.up) > 0.5 * np.linalg.norm(d_h) + 0.02:
                    continue
                score = ra + rb
                if best is None or score > best[0]:
                    best = (score, x, a, b)
    if best is None:
        return None
    _, x, a, b = best
    return x, _descend_longest(t, a), _descend_longest(t, b)


def _chain_side(t: _Tree, chain: list[int]) -> str | None:
    votes = {"left": 0, "right": 0}
    for b in chain:
        for n in t.names(b):
            s = name_side(n)
            if s:
                votes[s] += 1
    if votes["left"] != votes["right"]:
        return "left" if votes["left"] > votes["right"] else "right"
    return None


def _sides(t: _Tree, a: list[int], b: list[int], lateral: np.ndarray) -> tuple[list[int], list[int], str]:
    """(left chain, right chain, how the sides were told)."""
    sa, sb = _chain_side(t, a), _chain_side(t, b)
    if sa and sb and sa != sb:
        return (a, b, "name") if sa == "left" else (b, a, "name")
    if (sa and not sb) or (sb and not sa):
        if (sa or "") == "left" or (sb or "") == "right":
            return a, b, "name"
        return b, a, "name"
    ya = float(t.xpos[a[0]] @ lateral)
    yb = float(t.xpos[b[0]] @ lateral)
    if abs(ya - yb) < 1e-6:  # bases on the midline: compare the chains' mean lateral positions
        ya = float(np.mean([t.xpos[x] @ lateral for x in a]))
        yb = float(np.mean([t.xpos[x] @ lateral for x in b]))
    return (a, b, "position") if ya > yb else (b, a, "position")


# -- parts along a chain ---------------------------------------------------------------------


def _axes_point(t: _Tree, bodies: list[int]) -> np.ndarray | None:
    """The point closest (least squares) to the hinge axes of ``bodies`` (None for < 2 axes)."""
    A = np.zeros((3, 3))
    rhs = np.zeros(3)
    n = 0
    for b in bodies:
        for j in t.joints(b):
            if int(t.m.jnt_type[j]) != _HINGE:
                continue
            u = t.data.xaxis[j] / np.linalg.norm(t.data.xaxis[j])
            P = np.eye(3) - np.outer(u, u)
            A += P
            rhs += P @ t.data.xanchor[j]
            n += 1
    if n < 2 or np.linalg.matrix_rank(A, tol=1e-6) < 3:
        return None
    return np.linalg.solve(A, rhs)


def _by_name(t: _Tree, b: int, words: dict[str, str], how: str) -> str:
    """``name 'calf'``: the keyword of ``b``'s name (or of its joints' names) that told its part."""
    for n in t.names(b):
        hit = next((w for w in _tokens(n) if w in words), None)
        if hit:
            return f"name {hit!r}" + (f", {how}" if how else "")
    return "name" + (f", {how}" if how else "")


def _pick(t: _Tree, group: list[int], oriented: bool) -> tuple[int, str]:
    """The body of a part's group standing for its joint, and how it was picked."""
    art = [b for b in group if t.articulated(b)]
    if not art:
        return group[0], ""
    if len(art) == 1:
        return art[0], ""
    if oriented:
        return art[-1], f"last of {len(art)} articulated bodies"
    p = _axes_point(t, art)
    if p is None:
        return art[0], f"first of {len(art)} articulated bodies"
    dist = [float(np.linalg.norm(t.xpos[b] - p)) for b in art]
    best = min(range(len(art)), key=lambda i: (round(dist[i], 3), i))
    return art[best], f"nearest the joint axes' meeting point of {len(art)} bodies"


def _limb_words(t: _Tree, chain: list[int], words: dict[str, str]) -> set[str]:
    """Keywords that name the whole limb, not a part: on every articulated body of the chain
    (its name or its joints'), three or more (Atlas's ``l_leg_hpz``...``l_leg_akx``: the
    ``leg`` of each is the limb, not the knee; HRP's ``LLEG_JOINT0..5``)."""
    art = [b for b in chain if t.articulated(b)]
    if len(art) < 3:
        return set()
    per_body = [{w for n in t.names(b) for w in _tokens(n) if w in words} for b in art]
    return set.intersection(*per_body)


def _named_groups(t: _Tree, chain: list[int], words: dict[str, str]) -> list[tuple[str, list[int]]]:
    """Consecutive runs of bodies of ``chain`` whose names mention the same part (keywords
    that name the whole limb left out)."""
    limb = _limb_words(t, chain, words)
    groups: list[tuple[str, list[int]]] = []
    for b in chain:
        parts = []
        for n in t.names(b):
            parts = [words[w] for w in _tokens(n) if w in words and w not in limb]
            if parts:
                break
        part = parts[0] if parts else None
        if part is None:
            groups.append(("", [b]))
        elif groups and groups[-1][0] == part:
            groups[-1][1].append(b)
        else:
            groups.append((part, [b]))
    return groups


def _points(t: _Tree, chain: list[int]) -> list[list[int]]:
    """Articulation points of a chain: articulated bodies, merged when their origins are within 2 cm."""
    pts: list[list[int]] = []
    for b in chain:
        if not t.articulated(b):
            continue
        if pts and np.linalg.norm(t.xpos[b] - t.xpos[pts[-1][-1]]) < 0.02:
            pts[-1].append(b)
        else:
            pts.append([b])
    return pts


def _leg_parts(t: _Tree, chain: list[int]) -> dict[str, tuple[int, str]]:
    """``hip``/``knee``/``ankle``/``toe`` -> (body, why) for one leg."""
    groups = _named_groups(t, chain, _LEG_WORDS)
    named = {p: g for p, g in groups if p}
    out: dict[str, tuple[int, str]] = {}
    for part in ("hip", "knee", "ankle"):
        if part in named:
            b, how = _pick(t, named[part], oriented=(part == "ankle"))
            out[part] = (b, _by_name(t, b, _LEG_WORDS, how))
    # toe: a toe-named body after the ankle (or an articulated body beyond it)
    if "toe" in named:
        out["toe"] = (named["toe"][0], _by_name(t, named["toe"][0], _LEG_WORDS, ""))
    pts = _points(t, chain)
    if len(pts) >= 3:
        heights = [float(t.h[p[0]]) for p in pts]
        if "hip" not in out:
            b, how = _pick(t, pts[0], oriented=False)
            out["hip"] = (b, "tree position: first articulation point of the leg")
        if "ankle" not in out:
            # the last articulation point not level with the sole (a toe joint is)
            sole = min(heights)
            top = t.h[out["hip"][0]]
            cand = [i for i, p in enumerate(pts) if heights[i] > sole + 0.02 * (top - sole) or i == 0]
            i_ank = cand[-1] if len(cand) > 2 else len(pts) - 1
            # a point the leg reaches going more down than forward is no toe: the shank of a
            # small robot ends a few cm above the sole (the Berkeley Humanoid's, 5 cm)
            while i_ank < len(pts) - 1 and not _foot_step(t, pts[i_ank][0], pts[i_ank + 1][0]):
                i_ank += 1
            b, _ = _pick(t, pts[i_ank], oriented=True)
            out["ankle"] = (b, "tree position: last articulation point above the sole")
            if "toe" not in out and i_ank < len(pts) - 1:
                out["toe"] = (pts[i_ank + 1][0], "tree position: articulated body beyond the ankle")
        if "knee" not in out:
            hip_i = next(i for i, p in enumerate(pts) if out["hip"][0] in p) if any(out["hip"][0] in p for p in pts) else 0
            ank_i = next((i for i, p in enumerate(pts) if out["ankle"][0] in p), len(pts) - 1)
            mid = 0.5 * (t.h[out["hip"][0]] + t.h[out["ankle"][0]])
            between = list(range(hip_i + 1, ank_i))
            if between:
                i = min(between, key=lambda i: abs(heights[i] - mid))
                b, _ = _pick(t, pts[i], oriented=False)
                out["knee"] = (b, "tree position: articulation point at mid-leg")
    if "hip" in out and "knee" in out and out["hip"][1].startswith("tree position"):
        out["hip"] = _hip_centre(t, chain, out["hip"], out["knee"][0])
    if "hip" in out and "knee" in out:
        out["hip"] = _hip_over_knee(t, chain, out["hip"], out["knee"][0])
    if "toe" not in out and "ankle" in out:
        after = chain[chain.index(out["ankle"][0]) + 1:]
        art = [b for b in after if t.articulated(b)]
        if art:
            out["toe"] = (art[0], "tree position: articulated body beyond the ankle")
    return out


def _hip_centre(t: _Tree, chain: list[int], hip: tuple[int, str], knee: int) -> tuple[int, str]:
    """A hip told by tree position: among the articulated bodies before the knee (a hip whose
    yaw, roll and pitch hinges sit on bodies at separate origins, as the Berkeley Humanoid's),
    the body nearest the point closest to all their hinge axes (:func:`_axes_point`; ties: the
    earlier body), as a hip named by its bodies takes it."""
    if hip[0] not in chain or knee not in chain:
        return hip
    cand = [b for b in chain[chain.index(hip[0]): chain.index(knee)] if t.articulated(b)]
    p = _axes_point(t, cand) if len(cand) >= 2 else None
    if p is None:
        return hip
    best = min(cand, key=lambda b: (round(float(np.linalg.norm(t.xpos[b] - p)), 3), cand.index(b)))
    if best == hip[0]:
        return hip
    return best, f"tree position: nearest the joint axes' meeting point of the {len(cand)} bodies before the knee"


def _foot_step(t: _Tree, a: int, b: int) -> bool:
    """Whether going from body ``a``'s origin to ``b``'s in the rest pose goes further along the
    floor than down (ankle to toe along the foot), not down a segment (knee to ankle)."""
    d = t.xpos[b] - t.xpos[a]
    down = abs(float(d @ t.up))
    return float(np.linalg.norm(d - (d @ t.up) * t.up)) > down


def _distal(t: _Tree, chain: list[int], b: int) -> np.ndarray | None:
    """Unit direction from ``b``'s origin to the limb beyond it in the rest pose: the furthest
    body origin after it on the chain, else the middle of its own geoms (None: nothing beyond)."""
    after = [x for x in chain[chain.index(b) + 1:] if np.linalg.norm(t.xpos[x] - t.xpos[b]) > 0.02]
    if after:
        v = max((t.xpos[x] - t.xpos[b] for x in after), key=lambda v: float(np.linalg.norm(v)))
    else:
        geoms = [g for g in range(t.m.ngeom) if int(t.m.geom_bodyid[g]) in set(t.subtree(b))]
        if not geoms:
            return None
        v = np.mean([t.data.geom_xpos[g] for g in geoms], axis=0) - t.xpos[b]
    n = float(np.linalg.norm(v))
    return v / n if n > 0.02 else None


def _bends(t: _Tree, chain: list[int], b: int) -> bool:
    """Whether a hinge of ``b`` bends the limb (its axis more than 45 degrees off the limb beyond
    it) rather than turning it about its own length.  True where it cannot be told."""
    hinges = [j for j in t.joints(b) if int(t.m.jnt_type[j]) == _HINGE]
    d = _distal(t, chain, b)
    if not hinges or d is None:
        return True
    return any(abs(float(t.data.xaxis[j] @ d)) / (np.linalg.norm(t.data.xaxis[j]) + 1e-12) < math.cos(math.radians(45))
               for j in hinges)


def _bending_elbow(t: _Tree, chain: list[int], out: dict[str, tuple[int, str]]) -> None:
    """Move the elbow onto the first hinge that bends the arm, where the elbow's bodies only twist.

    Some vendors name the upper arm's twist body ``elbow`` and the forearm ``hand`` (its hinge
    at the forearm's root is the one that bends the arm).  Tracking the twist body as the elbow
    swings the real forearm out of the actor's.  The wrist then moves beyond the new elbow:
    the next articulation point 8 cm or more on, or none (the forearm ends the arm; its end
    becomes the wrist site in :func:`propose_mapping`).
    """
    e = out["elbow"][0]
    group = next((p for p in _points(t, chain) if e in p), [e])
    if any(_bends(t, chain, b) for b in group):
        return
    later = [b for b in chain[chain.index(group[-1]) + 1:] if t.articulated(b)]
    new = next((b for b in later if _bends(t, chain, b)), None)
    if new is None:
        return
    out["elbow"] = (new, f"joint axes: the first hinge that bends the arm ({t.name(e)!r} turns about the upper arm)")
    w = out.get("wrist")
    if w is not None and chain.index(w[0]) <= chain.index(new):
        del out["wrist"]
        beyond = [p for p in _points(t, chain) if chain.index(p[0]) > chain.index(new)
                  and np.linalg.norm(t.xpos[p[0]] - t.xpos[new]) > 0.08]
        if beyond:
            b, _ = _pick(t, beyond[0], oriented=False)
            out["wrist"] = (b, "tree position: articulation point 8 cm or more beyond the elbow")


def _shoulder_centre(t: _Tree, chain: list[int], out: dict[str, tuple[int, str]]) -> None:
    """The shoulder: the body nearest the meeting point of every hinge between the clavicle
    (or the arm's root) and the elbow, where that is not the body the names gave.

    Atlas names its upper arm's twist body ``uarm``, 19 cm out from the ``scap`` body whose
    hinge lifts the arm: a shoulder there rides the chest where the arm was, not where it
    turns.  Where the shoulder's bodies hold all the hinges before the elbow (the usual
    pitch/roll/yaw bodies) nothing changes.
    """
    if "shoulder" not in out or "elbow" not in out:
        return
    start = chain.index(out["clavicle"][0]) + 1 if "clavicle" in out else 0
    e = chain.index(out["elbow"][0])
    cand = [b for b in chain[start:e] if t.articulated(b)]
    s0 = out["shoulder"][0]
    if len(cand) < 2 or s0 not in cand:
        return
    p = _axes_point(t, cand)
    if p is None:
        return
    best = min(cand, key=lambda b: (round(float(np.linalg.norm(t.xpos[b] - p)), 3), cand.index(b)))
    if best == s0 or np.linalg.norm(t.xpos[s0] - p) <= np.linalg.norm(t.xpos[best] - p) + 0.02:
        return
    out["shoulder"] = (best, f"joint axes: nearest the meeting point of the {len(cand)} bodies' hinges before the "
                             f"elbow ({t.name(s0)!r}, named, is {np.linalg.norm(t.xpos[s0] - p) * 100:.0f} cm from it)")


def _forearm_ends(t: _Tree, elbows: dict[str, int]) -> dict[str, tuple[str, int, tuple[float, float, float]]]:
    """Side -> (site name, elbow body, position in its frame) of the end of a forearm with no
    wrist: the furthest point of its geoms (collision ones if any) along the forearm."""
    from .geometry import geom_candidates, is_visual_only

    taken = {t.m.site(i).name for i in range(t.m.nsite)}
    out = {}
    for side, e in elbows.items():
        bodies = set(t.subtree(e))
        geoms = [g for g in range(t.m.ngeom) if int(t.m.geom_bodyid[g]) in bodies]
        solid = [g for g in geoms if not is_visual_only(t.m, g) and (t.m.geom_contype[g] or t.m.geom_conaffinity[g])]
        pts = []
        for g in solid or geoms:
            cand = geom_candidates(t.m, g)
            if len(cand):
                R = t.data.geom_xmat[g].reshape(3, 3)
                pts.append(t.data.geom_xpos[g] + cand[:, :3] @ R.T)
        if not pts:
            continue
        P = np.concatenate(pts)
        x = t.xpos[e]
        d = P.mean(axis=0) - x
        if np.linalg.norm(d) < 0.02:
            continue
        d /= np.linalg.norm(d)
        reach = float(np.max((P - x) @ d))
        if reach < 0.08:
            continue
        Rb = t.data.xmat[e].reshape(3, 3)
        local = Rb.T @ (reach * d)
        name = f"{side}_forearm_end"
        while name in taken:
            name += "_proposed"
        out[side] = (name, e, tuple(round(float(v), 4) + 0.0 for v in local))
    return out


def _hip_over_knee(t: _Tree, chain: list[int], hip: tuple[int, str], knee: int) -> tuple[int, str]:
    """The hip's body, moved along the hip's bodies onto the thigh's line where the hip is offset.

    A hip whose yaw and roll bodies sit inward of its pitch body (a thigh hung on an offset
    flexion joint) puts the knee 10 cm or more sideways of the axes' meeting point in the
    standing rest pose: hip -> knee is then no longer the thigh's direction, and an actor's
    straight leg pulls the knee inwards (hip roll at its limit).  Among the articulated bodies
    from the hip down to the knee and level with the hip (within a quarter of the thigh), the
    hip keeps its body unless its origin is further, horizontally, from the knee than the
    nearest one by more than max(2 cm, 10 % of the thigh); then the nearest of those takes it.
    """
    b0, why = hip
    if b0 not in chain or knee not in chain:
        return hip
    thigh = float(np.linalg.norm(t.xpos[knee] - t.xpos[b0]))
    if thigh < 1e-6:
        return hip
    cand = [b for b in chain[chain.index(b0): chain.index(knee)]
            if t.articulated(b) and abs(t.h[b] - t.h[b0]) <= 0.25 * thigh]

    def off(b: int) -> float:
        v = t.xpos[knee] - t.xpos[b]
        return float(np.linalg.norm(v - (v @ t.up) * t.up))

    if len(cand) < 2:
        return hip
    best = min(cand, key=lambda b: (round(off(b), 3), cand.index(b)))
    if off(b0) <= off(best) + max(0.02, 0.1 * thigh):
        return hip
    return best, (f"{why.split(',')[0]}, the hip body over the knee "
                  f"({off(b0) * 100:.0f} cm sideways of it from {t.name(b0)!r})")


def _arm_parts(t: _Tree, chain: list[int]) -> dict[str, tuple[int, str]]:
    """``clavicle``/``shoulder``/``elbow``/``wrist``/``hand_end`` -> (body, why) for one arm."""
    groups = _named_groups(t, chain, _ARM_WORDS)
    # "shoulder" then a distinct "arm" body: the first is a clavicle (LeftShoulder -> LeftArm)
    merged: list[tuple[str, list[int]]] = []
    for part, g in groups:
        if merged and merged[-1][0] == part and part:
            merged[-1][1].extend(g)
        else:
            merged.append((part, list(g)))
    named: dict[str, list[int]] = {}
    for part, g in merged:
        if part and part not in named:
            named[part] = g
    sh = named.get("shoulder", [])
    if len(sh) >= 2:
        tokens = [set(_tokens(t.name(b))) for b in sh]
        arm_only = [i for i, tk in enumerate(tokens) if "shoulder" not in tk]
        sh_only = [i for i, tk in enumerate(tokens) if "shoulder" in tk]
        if arm_only and sh_only and max(sh_only) < min(arm_only):
            a, b = sh[max(sh_only)], sh[min(arm_only)]
            if np.linalg.norm(t.xpos[a] - t.xpos[b]) > 0.05 and "clavicle" not in named:
                named["clavicle"] = [sh[i] for i in sh_only]
                named["shoulder"] = [sh[i] for i in arm_only]
    out: dict[str, tuple[int, str]] = {}
    if "clavicle" in named:
        b, how = _pick(t, named["clavicle"], oriented=False)
        out["clavicle"] = (b, _by_name(t, b, _ARM_WORDS, how))
    for part in ("shoulder", "elbow"):
        if part in named:
            b, how = _pick(t, named[part], oriented=False)
            out[part] = (b, _by_name(t, b, _ARM_WORDS, how))
    wrist_group = named.get("wrist")
    rigid_hand = False
    if wrist_group is None and "hand" in named:
        if any(t.articulated(b) for b in named["hand"]):
            wrist_group = named["hand"]
        elif "elbow" in out and np.linalg.norm(t.xpos[named["hand"][0]] - t.xpos[out["elbow"][0]]) > 0.08:
            wrist_group, rigid_hand = named["hand"][:1], True  # a hand fixed at the forearm's end
    if wrist_group is not None:
        b, how = _pick(t, wrist_group, oriented=False)
        out["wrist"] = (b, _by_name(t, b, _ARM_WORDS, "fixed at the end of the forearm" if rigid_hand else how))
    pts = _points(t, chain)
    if "shoulder" not in out and pts:
        b, _ = _pick(t, pts[0], oriented=False)
        out["shoulder"] = (b, "tree position: first articulation point of the arm")
    if "elbow" not in out:
        s_i = next((i for i, p in enumerate(pts) if out["shoulder"][0] in p), 0)
        # the elbow: the first articulation point clearly away (> 8 cm) from the shoulder
        far = [i for i in range(s_i + 1, len(pts))
               if np.linalg.norm(t.xpos[pts[i][0]] - t.xpos[out["shoulder"][0]]) > 0.08]
        if far:
            b, _ = _pick(t, pts[far[0]], oriented=False)
            out["elbow"] = (b, "tree position: first articulation point 8 cm or more from the shoulder")
            if "wrist" not in out:
                e_pt = far[0]
                far2 = [i for i in range(e_pt + 1, len(pts))
                        if np.linalg.norm(t.xpos[pts[i][0]] - t.xpos[b]) > 0.08]
                if far2:
                    w, _ = _pick(t, [x for i in far2 for x in pts[i]
                                     if np.linalg.norm(t.xpos[x] - t.xpos[pts[far2[0]][0]]) < 0.1], oriented=False)
                    out["wrist"] = (w, "tree position: articulation point 8 cm or more beyond the elbow")
    if "elbow" in out:
        _bending_elbow(t, chain, out)
        _shoulder_centre(t, chain, out)
    if "wrist" in out:
        last = chain[-1]
        w = out["wrist"][0]
        if last != w and chain.index(last) > chain.index(w) and np.linalg.norm(t.xpos[last] - t.xpos[w]) > 0.02:
            out["hand_end"] = (last, "tree position: end of the arm chain")
    return out


# -- the whole body --------------------------------------------------------------------------


def propose_mapping(path: str | os.PathLike) -> Proposal:
    """Propose a mapping for the humanoid MJCF at ``path`` (see the module docstring).

    Raises:
        InputError: the file is missing or MuJoCo cannot load it.
        MappingError: no free joint, no recognisable legs (arms are optional).
    """
    p = Path(path)
    model = _load(p)
    free = [j for j in range(model.njnt) if int(model.jnt_type[j]) == _FREE]
    if not free:
        raise MappingError("no free joint: a character needs a floating base (<freejoint/> on its root body)", path=p)
    if len(free) > 1:
        raise MappingError(f"{len(free)} free joints: a character has exactly one floating base", path=p)
    root = int(model.jnt_bodyid[free[0]])
    qpos, key = _rest(model)
    t = _Tree(model, qpos)
    notes: list[str] = []

    pelvis, leg_a, leg_b = _find_legs(t, root, p)
    # lateral axis of the MuJoCo convention (faces +X): left = up x forward
    fwd0 = np.array([1.0, 0.0, 0.0]) if abs(t.up[0]) < 0.5 else np.array([0.0, 1.0, 0.0])
    lateral = np.cross(t.up, fwd0)
    left_leg, right_leg, leg_how = _sides(t, leg_a, leg_b, lateral)
    if leg_how == "name":
        d = t.xpos[left_leg[0]] - t.xpos[right_leg[0]]
        d = d - (d @ t.up) * t.up
        if np.linalg.norm(d) < 1e-6:
            d = np.mean([t.xpos[x] for x in left_leg], axis=0) - np.mean([t.xpos[x] for x in right_leg], axis=0)
            d = d - (d @ t.up) * t.up
        forward = _snap(np.cross(d, t.up)) if np.linalg.norm(d) > 1e-6 else fwd0
    else:
        forward = fwd0
        notes.append("legs told apart by position: the model is assumed to face +X (MuJoCo's convention)")
    lateral = np.cross(t.up, forward)

    joints: dict[str, Guess] = {}
    left_out: dict[str, str] = {}

    def put(canon: str, body: int, why: str) -> None:
        joints[canon] = Guess(canon, "body", t.name(body), why)

    put("pelvis", pelvis, "the free-joint body" if pelvis == root else "tree position: where the legs branch")

    for side, chain, how in (("left", left_leg, leg_how), ("right", right_leg, leg_how)):
        parts = _leg_parts(t, chain)
        for part in ("hip", "knee", "ankle"):
            if part not in parts:
                raise MappingError(f"no recognisable legs: cannot tell the {side} {part} on the chain "
                                   f"{', '.join(t.name(b) for b in chain)}", path=p)
        for part in ("hip", "knee", "ankle", "toe"):
            if part in parts:
                body, why = parts[part]
                put(f"{side}_{part}", body, why + ("" if how == "name" else "; side by position"))

    arms = _find_arms(t, root, pelvis, [left_leg, right_leg])
    arm_chains: dict[str, list[int]] = {}
    if arms is None:
        _leave_out_arms(("left", "right"), "no pair of chains on opposite sides of the trunk", left_out, notes)
        arm_root = None
    else:
        arm_root, arm_a, arm_b = arms
        left_arm, right_arm, arm_how = _sides(t, arm_a, arm_b, lateral)
        untold: dict[str, str] = {}  # side -> why its arm is left out
        for side, chain in (("left", left_arm), ("right", right_arm)):
            parts = _arm_parts(t, chain)
            lack = [part for part in ("shoulder", "elbow") if part not in parts]
            if lack:
                untold[side] = f"cannot tell the {' or '.join(lack)} on the chain {', '.join(t.name(b) for b in chain)}"
                continue
            arm_chains[side] = chain
            for part in ("clavicle", "shoulder", "elbow", "wrist", "hand_end"):
                if part in parts:
                    body, why = parts[part]
                    put(f"{side}_{part}", body, why + ("" if arm_how == "name" else "; side by position"))
        if untold:
            _leave_out_arms(tuple(untold), "; ".join(untold.values()), left_out, notes)

    ends = _forearm_ends(t, {side: model.body(joints[f"{side}_elbow"].name).id for side in arm_chains
                             if f"{side}_wrist" not in joints})
    for side, (site, body, pos) in ends.items():
        joints[f"{side}_wrist"] = Guess(f"{side}_wrist", "site", site, "no wrist joint: the end of the forearm's geoms")
    if (_axis_name(t.up), _axis_name(forward)) == ("Z", "X"):
        sites = _ball_sites(t, {side: model.body(joints[f"{side}_ankle"].name).id
                                for side in ("left", "right") if f"{side}_toe" not in joints})
        for side, (site, body, pos) in sites.items():
            joints[f"{side}_toe"] = Guess(f"{side}_toe", "site", site, "no toe body: the ball of the rigid foot, "
                                          "3/4 of the sole from the heel, 1/3 of the ankle height up")
    else:
        sites = {}
    centres = _hinge_centres(t, joints, {n: (b, pos) for n, b, pos in list(sites.values()) + list(ends.values())})
    for canon, (site, body, pos) in centres.items():
        joints[canon] = Guess(canon, "site", site, joints[canon].why + "; moved along its hinge onto the limb's line")

    legs = [left_leg, right_leg]
    if arm_root is not None:
        trunk = _trunk_path(t, pelvis, arm_root)
        head_chain = _head_branch(t, arm_root, list(arms[1:]), trunk + [pelvis], legs)
        below = " below the arms"
    else:
        trunk = _trunk_path(t, pelvis, _trunk_top(t, root, legs))
        trunk, head_chain = _split_named_head(t, trunk)
        below = ""
    groups = _trunk_groups(t, pelvis, trunk)
    if groups:
        put("spine", groups[0][-1], "tree position: first trunk joint above the pelvis")
        if len(groups) >= 2:
            put("chest", groups[-1][-1], "tree position: last trunk joint" + below)
    if head_chain:
        _put_head(t, head_chain, put, left_out)
    else:
        reason = "no head joint" if any(
            "head" in name_parts(t.name(b), _HEAD_WORDS) or "neck" in name_parts(t.name(b), _HEAD_WORDS)
            for b in t.subtree(root)) else "no head or neck body"
        for c in ("neck", "head"):
            left_out[c] = reason

    for canon in CANONICAL_NAMES:
        if canon not in joints and canon not in left_out:
            left_out[canon] = _missing_reason(canon)

    rest_joints, rest_note = _rest_fix(t, joints, key, {c: b for c, (_, b, _) in centres.items()})
    name = p.stem
    return Proposal(
        mjcf=p,
        name=name,
        up=_axis_name(t.up),
        forward=_axis_name(forward),
        joints=joints,
        left_out=left_out,
        rest_keyframe=key,
        rest_joints=rest_joints,
        rest_note=rest_note,
        notes=notes,
        sites={site: (model.body(body).name, pos)
               for site, body, pos in list(sites.values()) + list(ends.values()) + list(centres.values())},
    )


#: Canonical joints of one side's arm, as the proposal leaves them out.
_ARM_PARTS = ("clavicle", "shoulder", "elbow", "wrist", "hand_end")


def _leave_out_arms(sides: tuple[str, ...], why: str, left_out: dict[str, str], notes: list[str]) -> None:
    """Leave ``sides``' arms out of the proposal (the loader takes a character without them,
    :data:`~physmocap.models.character.OPTIONAL_LIMBS`), saying so in a note."""
    what = "no arms" if len(sides) == 2 else f"no {sides[0]} arm"
    for side in sides:
        for part in _ARM_PARTS:
            left_out[f"{side}_{part}"] = what
    whose = "the arms of the actor are" if len(sides) == 2 else f"the actor's {sides[0]} arm is"
    notes.append(f"{what}: {whose} not tracked ({why})")


def _trunk_path(t: _Tree, pelvis: int, top: int) -> list[int]:
    """The bodies on the tree path from the pelvis (excluded) to ``top`` (included), through
    their common ancestor: the top may hang on the pelvis's parent, as when the free body is
    the torso and the legs hang from a waist below it."""
    up_a = t.path_up(pelvis, 0)
    up_b = t.path_up(top, 0)
    lca = next(x for x in up_a if x in set(up_b))
    rising = up_a[: up_a.index(lca) + 1]  # pelvis ... lca
    falling = list(reversed(up_b[: up_b.index(lca)]))  # below lca ... top
    return [b for b in rising[1:] + falling if b > 0]


def _turns(t: _Tree, pelvis: int, b: int) -> bool:
    """Whether trunk body ``b`` turns relative to the body below it on the way up from the
    pelvis: its own joints where it is below the pelvis's ancestors, else (on the pelvis's
    path to the root, where the pelvis turns under it) its child's on that path."""
    up = t.path_up(pelvis, 0)
    if b in up:
        return t.articulated(up[up.index(b) - 1])
    return t.articulated(b)


def _trunk_groups(t: _Tree, pelvis: int, trunk: list[int]) -> list[list[int]]:
    """Articulation points of the trunk above the pelvis: bodies that turn, merged with the
    fixed bodies above them and with bodies within 2 cm; none at the pelvis's own origin (a
    waist yaw body sharing it)."""
    groups: list[list[int]] = []
    for b in trunk:
        moves = _turns(t, pelvis, b)
        if not moves and not groups:
            continue
        if np.linalg.norm(t.xpos[b] - t.xpos[pelvis]) < 0.02:
            continue  # a joint at the pelvis itself (a waist yaw body sharing its origin)
        if groups and (not moves or np.linalg.norm(t.xpos[b] - t.xpos[groups[-1][-1]]) < 0.02):
            groups[-1].append(b)
        else:
            groups.append([b])
    return groups


def _head_branch(t: _Tree, arm_root: int, arms: list[list[int]], trunk: list[int], legs: list[list[int]]) -> list[int]:
    """The head of a robot with arms: the longest articulated branch of the arms' body, not
    an arm, the trunk or a leg, rising above the shoulders (empty if none)."""
    arm_set = set(t.subtree(arms[0][0])) | set(t.subtree(arms[1][0]))
    trunk_set = set(trunk) | set(t.subtree(legs[0][0])) | set(t.subtree(legs[1][0]))
    shoulder_h = 0.5 * (t.h[arms[0][0]] + t.h[arms[1][0]])
    head_chain: list[int] = []
    for c in t.children[arm_root]:
        if c in arm_set or c in trunk_set:
            continue
        if not any(t.articulated(x) for x in t.subtree(c)):
            continue
        chain = _descend_longest(t, c)
        if max(t.h[x] for x in chain) > shoulder_h and len(chain) > len(head_chain):
            head_chain = chain
    return head_chain


def _trunk_top(t: _Tree, root: int, legs: list[list[int]]) -> int:
    """The top of the trunk of a robot without arms: the highest body origin of the free
    body's tree outside the legs (the earlier body on a tie); the pelvis's side of the tree
    when nothing rises above it."""
    legs_set = set(t.subtree(legs[0][0])) | set(t.subtree(legs[1][0]))
    rest = [b for b in sorted(t.subtree(root)) if b not in legs_set]
    return max(rest, key=lambda b: (round(float(t.h[b]), 6), -b))


def _split_named_head(t: _Tree, trunk: list[int]) -> tuple[list[int], list[int]]:
    """(trunk, head chain) of a trunk path with no arms to tell where the chest ends: the head
    chain starts at the first body whose name (or its joints') says neck or head; with no
    such name the whole path is trunk."""
    for i, b in enumerate(trunk):
        if any(part in ("neck", "head") for n in t.names(b) for part in name_parts(n, _HEAD_WORDS)):
            return trunk[:i], trunk[i:]
    return trunk, []


def _put_head(t: _Tree, head_chain: list[int], put, left_out: dict[str, str]) -> None:
    """Neck and head on a head chain (its articulation points); a single one is the head."""
    pts = _points(t, head_chain)
    if not pts:
        for c in ("neck", "head"):
            left_out[c] = "no head joint"
        return
    by_name = {part: g for part, g in _named_groups(t, head_chain, _HEAD_WORDS) if part}
    if len(pts) == 1:
        # neck and head turn in one body: it is the head (its frame follows the actor's head)
        b = _pick(t, pts[0], oriented=True)[0]
        put("head", b, _by_name(t, b, _HEAD_WORDS, "the only joint of the head branch")
            if "head" in by_name or "neck" in by_name else "tree position: the only joint of the head branch")
        left_out["neck"] = "no neck joint apart from the head's"
        return
    neck_pt = next((g for g in pts if any(x in by_name.get("neck", []) for x in g)), pts[0])
    head_pt = next((g for g in reversed(pts) if any(x in by_name.get("head", []) for x in g)), pts[-1])
    if head_pt is neck_pt:
        head_pt = pts[-1]
    b = _pick(t, neck_pt, oriented=False)[0]
    put("neck", b, _by_name(t, b, _HEAD_WORDS, "") if "neck" in by_name else
        "tree position: first joint of the head branch")
    b = _pick(t, head_pt, oriented=True)[0]
    put("head", b, _by_name(t, b, _HEAD_WORDS, "") if "head" in by_name else
        "tree position: last joint of the head branch")


#: A knee or elbow whose body origin is further than this (m) from its hinge's point on the
#: limb's line gets a site there (as articulation points closer than this are one).
_OFF_LINE = 0.02


def _hinge_centres(t: _Tree, joints: dict[str, Guess], sites: dict[str, tuple[int, tuple]]):
    """Canonical -> (site name, body, position in its frame) for each knee or elbow whose body
    origin sits along its hinge's axis away from the limb (the Berkeley Humanoid's knee body, 3
    cm out from the line from hip to ankle): a site at the point of the hinge axis nearest the
    line from the limb's first to its last joint (closest points of two lines), where that point
    is more than :data:`_OFF_LINE` from the origin.

    Tracking the origin bows the limb in the frontal plane: on the CMU walk the Berkeley
    Humanoid's shanks were 12 degrees off the actor's, 3 to 6 with the site.  A body with
    more than one hinge (a knee that also turns) is left as it is: no one axis to slide along.
    """
    def point(canon: str) -> np.ndarray | None:
        g = joints.get(canon)
        if g is None:
            return None
        if g.kind == "body":
            return t.xpos[t.m.body(g.name).id]
        body, pos = sites[g.name]
        return t.data.xpos[body] + t.data.xmat[body].reshape(3, 3) @ np.asarray(pos, dtype=float)

    taken = {t.m.site(i).name for i in range(t.m.nsite)} | set(sites)
    out = {}
    for side in ("left", "right"):
        for first, mid, last in (("hip", "knee", "ankle"), ("shoulder", "elbow", "wrist")):
            g = joints.get(f"{side}_{mid}")
            a, c = point(f"{side}_{first}"), point(f"{side}_{last}")
            if g is None or g.kind != "body" or a is None or c is None:
                continue
            b = t.m.body(g.name).id
            hinges = [j for j in t.joints(b) if int(t.m.jnt_type[j]) == _HINGE]
            if len(hinges) != 1 or np.linalg.norm(c - a) < 1e-6:
                continue
            u = t.data.xaxis[hinges[0]] / np.linalg.norm(t.data.xaxis[hinges[0]])
            d = (c - a) / np.linalg.norm(c - a)
            w = t.data.xanchor[hinges[0]] - a
            den = 1.0 - float(u @ d) ** 2
            if den < 1e-6:
                continue  # the axis along the limb: no nearest point
            k = (float(u @ d) * float(d @ w) - float(u @ w)) / den
            centre = t.data.xanchor[hinges[0]] + k * u
            if np.linalg.norm(centre - t.xpos[b]) <= _OFF_LINE:
                continue
            local = t.data.xmat[b].reshape(3, 3).T @ (centre - t.xpos[b])
            name = f"{side}_{mid}_centre"
            while name in taken:
                name += "_proposed"
            taken.add(name)
            out[f"{side}_{mid}"] = (name, b, tuple(round(float(v), 4) + 0.0 for v in local))
    return out


def _ball_sites(t: _Tree, ankles: dict[str, int]) -> dict[str, tuple[str, int, tuple[float, float, float]]]:
    """Side -> (site name, ankle body, position in its frame) of the ball of a foot with no toe body."""
    from .footprint import foot_contact_points

    if not ankles:
        return {}
    found = foot_contact_points(t.m, t.data.qpos, ankles)
    taken = {t.m.site(i).name for i in range(t.m.nsite)}
    out = {}
    for side, points in found.items():
        body = ankles[side]
        R, x = t.data.xmat[body].reshape(3, 3), t.data.xpos[body]
        heel, toe = (R @ pos + x for _, _, pos in points)
        ball = heel + 0.75 * (toe - heel)
        sole = min(heel[2], toe[2])
        ball[2] = sole + (x[2] - sole) / 3.0
        local = R.T @ (ball - x)
        name = f"{side}_ball"
        while name in taken:
            name += "_proposed"
        out[side] = (name, body, tuple(round(float(v), 4) + 0.0 for v in local))
    return out


def _missing_reason(canon: str) -> str:
    stem = canon.split("_", 1)[1] if canon.startswith(("left_", "right_")) else canon
    return {
        "chest": "one trunk joint at most",
        "spine": "no trunk joint above the pelvis",
        "head_end": "no head tip body",
        "clavicle": "no clavicle body",
        "wrist": "no wrist body",
        "hand_end": "no hand beyond the wrist",
        "toe": "no toe body",
        "toe_end": "no toe tip body",
    }.get(stem, "not found")


def _bend_deg(t: _Tree, d: mujoco.MjData, a: int, b: int, c: int) -> float:
    u = d.xpos[b] - d.xpos[a]
    v = d.xpos[c] - d.xpos[b]
    cos = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v) + 1e-12))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def _rest_fix(t: _Tree, joints: dict[str, Guess], key: str | None,
              site_bodies: dict[str, int] | None = None) -> tuple[dict[str, float], str]:
    """With no keyframe: straighten elbows and knees the zero pose bends (hinge of the middle body).
    ``site_bodies``: canonical joint -> body of a site proposed on it (a knee's centre)."""
    if key is not None:
        return {}, f"keyframe {key!r}"
    m = t.m
    d = mujoco.MjData(m)
    d.qpos[:] = t.data.qpos
    body = {c: m.body(g.name).id for c, g in joints.items() if g.kind == "body"}
    body.update(site_bodies or {})
    fixes: dict[str, float] = {}
    notes = []
    # a zero outside a joint's range: the nearest bound (0.1 degree inside, as the file rounds)
    clamped = []
    for j in range(m.njnt):
        if int(m.jnt_type[j]) not in (_HINGE, _SLIDE) or not m.jnt_limited[j]:
            continue
        adr = int(m.jnt_qposadr[j])
        lo, hi = (float(v) for v in m.jnt_range[j])
        if lo <= d.qpos[adr] <= hi:
            continue
        k, step = (180.0 / math.pi, 10.0) if int(m.jnt_type[j]) == _HINGE else (1.0, 1e4)
        v = math.ceil(lo * k * step) / step if d.qpos[adr] < lo else math.floor(hi * k * step) / step
        v = min(max(v, lo * k), hi * k)
        d.qpos[adr] = v / k
        fixes[m.joint(j).name] = float(v)
        clamped.append(m.joint(j).name)
    if clamped:
        notes.append(f"{', '.join(clamped)} set to the nearest end of their range (zero is outside it)")
    limbs = {
        "arm": (("shoulder", "elbow", "wrist"), ("shoulder", "elbow", "hand_end")),
        "leg": (("hip", "knee", "ankle"),),
    }
    for side in ("left", "right"):
        for limb, options in limbs.items():
            triple = next((o for o in options if all(f"{side}_{x}" in body for x in o)), None)
            if triple is None:
                continue
            ka, kb, kc = (body[f"{side}_{x}"] for x in triple)
            mujoco.mj_kinematics(m, d)
            bend = _bend_deg(t, d, ka, kb, kc)
            if bend <= 20.0:
                continue
            hinges = [j for x in [kb] + _bodies_between(t, kb, kc) for j in t.joints(x)
                      if int(m.jnt_type[j]) == _HINGE]
            # the hinge that straightens the limb most (1-degree grid over its range)
            best = None
            for j in dict.fromkeys(hinges):
                adr = int(m.jnt_qposadr[j])
                lo, hi = (m.jnt_range[j] if m.jnt_limited[j] else (-math.pi, math.pi))
                keep = d.qpos[adr]
                for deg in range(int(math.ceil(math.degrees(lo))), int(math.floor(math.degrees(hi))) + 1):
                    d.qpos[adr] = math.radians(deg)
                    mujoco.mj_kinematics(m, d)
                    e = _bend_deg(t, d, ka, kb, kc)
                    if best is None or e < best[0] - 1e-9:
                        best = (e, j, deg)
                d.qpos[adr] = keep
            if best is not None and best[0] < bend - 10.0:
                e, j, deg = best
                d.qpos[int(m.jnt_qposadr[j])] = math.radians(deg)
                fixes[m.joint(j).name] = float(deg)
                notes.append(f"{m.joint(j).name} = {deg} deg straightens the {side} {limb} "
                             f"(bent {bend:.0f} deg at zero)")
    note = f"zero pose (no keyframe named {', '.join(repr(w) for w in REST_KEY_WORDS)})"
    if notes:
        note += ", with " + "; ".join(notes)
    return fixes, note


def _bodies_between(t: _Tree, top: int, bottom: int) -> list[int]:
    """Bodies from ``bottom`` up to (not including) ``top``, if ``top`` is an ancestor."""
    path = t.path_up(bottom, top)
    return path[:-1] if path and path[-1] == top else []
