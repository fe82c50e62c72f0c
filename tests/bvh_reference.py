"""A deliberately simple BVH reader and forward kinematics, independent of physmocap's:
regexes for OFFSET/CHANNELS/braces, rotations from scipy, file units and axes.  The reader
tests check physmocap's world positions against it; the vendor fixtures' generator reads
the bundled walk with it."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass
class BvhText:
    names: list[str]          # end sites named "<parent>_End"
    parents: list[int]
    offsets: np.ndarray       # (J, 3), file units
    channels: list[list[str]]
    rows: list[str]           # the frame rows, unparsed


def parse(path: str | Path) -> BvhText:
    text = Path(path).read_text()
    head, motion = re.split(r"(?m)^\s*MOTION\s*$", text, maxsplit=1)
    names, parents, offsets, chans, stack, last = [], [], [], [], [], -1
    for line in head.splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] in ("ROOT", "JOINT", "End"):
            names.append(tok[1] if tok[0] != "End" else names[stack[-1]] + "_End")
            parents.append(stack[-1] if stack else -1)
            chans.append([])
            last = len(parents) - 1
        elif tok[0] == "{":
            stack.append(last)
        elif tok[0] == "}":
            stack.pop()
        elif tok[0] == "OFFSET":
            offsets.append([float(v) for v in tok[1:4]])
        elif tok[0] == "CHANNELS":
            chans[-1] = tok[2:]
    return BvhText(names, parents, np.array(offsets, dtype=float), chans, motion.strip().splitlines()[2:])


def world(bvh: BvhText, frames) -> tuple[list[Rotation], np.ndarray]:
    """World rotations (one scipy Rotation per joint, over the frames) and world positions
    ``(F, J, 3)`` of ``frames``, in file units and axes."""
    vals = np.array([[float(v) for v in bvh.rows[f].split()] for f in frames])
    F, k = len(vals), 0
    G, P = [None] * len(bvh.parents), np.zeros((F, len(bvh.parents), 3))
    for j, p in enumerate(bvh.parents):
        t = np.tile(bvh.offsets[j], (F, 1))
        axes, angles = "", []
        for c in bvh.channels[j]:
            if c.endswith("position"):
                t[:, "XYZ".index(c[0])] = vals[:, k]
            else:
                axes += c[0]
                angles.append(vals[:, k])
            k += 1
        local = Rotation.from_euler(axes, np.stack(angles, 1), degrees=True) if axes else Rotation.identity(F)
        if p < 0:
            G[j], P[:, j] = local, t
        else:
            G[j], P[:, j] = G[p] * local, P[:, p] + G[p].apply(t)
    return G, P
