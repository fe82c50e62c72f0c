#!/usr/bin/env python3
"""The compiled floor of a retarget: what the same IK would cost with no Python around it.

Retargets a shared clip onto a character once (default options, planting on) and measures:

* **QPs per source frame**, over every pass (the tracking pass, the arm and transition
  passes, the velocity-cap passes);
* **MuJoCo C calls per QP** (``mj_kinematics``, ``mj_comPos``, ``mj_jacSite``, ``mj_jac``,
  ``mj_jacBody``, ``mj_geomDistance``: every call of the run, counted by :mod:`cProfile`,
  divided by its QPs; the few made outside the iterations, for the figures and the contact
  plan, count too, so the floor errs high) and the cost of one call of each, timed on its
  own (microseconds, wall);
* **daqp** on every QP the run solved, captured and solved again on its own (with its
  warm start): the solver's C time plus its Python call;

and prints the floor, (C calls + daqp) per QP times QPs per frame, as frames per second, next
to the run's own CPU frames per second: the share of a frame that is the interpreter's.  The
machine's speed drifts between minutes, so compare the two figures of one run.

Usage:  python scripts/bench_floor.py [--clip cmu_12_01_walk.bvh] [--character humanoid]
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHYSMOCAP_SHARED_DATA", REPO.parent / "shared" / "data"))
#: The MuJoCo functions the IK calls per iteration.
C_CALLS = ("mj_kinematics", "mj_comPos", "mj_jacSite", "mj_jac", "mj_jacBody", "mj_geomDistance")


def _per_call_us(f, repeat: int) -> float:
    t = time.perf_counter()
    for _ in range(repeat):
        f()
    return (time.perf_counter() - t) / repeat * 1e6


def _c_costs(character) -> dict[str, float]:
    """Microseconds per call of each of :data:`C_CALLS` on ``character`` in its rest pose
    (``mj_geomDistance`` between two of its collision geoms on different bodies)."""
    import mujoco

    model = character.model
    data = mujoco.MjData(model)
    data.qpos[:] = character.rest_qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    jac = np.zeros((3, model.nv))
    body = model.nbody - 1
    point = data.xpos[body].copy()
    geoms = [g for g in range(model.ngeom) if model.geom_contype[g] or model.geom_conaffinity[g]]
    pair = next(((a, b) for a in geoms for b in geoms if model.geom_bodyid[a] != model.geom_bodyid[b]), None)
    fromto = np.zeros(6)
    costs = {
        "mj_kinematics": _per_call_us(lambda: mujoco.mj_kinematics(model, data), 5000),
        "mj_comPos": _per_call_us(lambda: mujoco.mj_comPos(model, data), 5000),
        "mj_jacSite": _per_call_us(lambda: mujoco.mj_jacSite(model, data, jac, None, 0), 20000) if model.nsite else 0.0,
        "mj_jac": _per_call_us(lambda: mujoco.mj_jac(model, data, jac, None, point, body), 20000),
        "mj_jacBody": _per_call_us(lambda: mujoco.mj_jacBody(model, data, jac, None, body), 20000),
        "mj_geomDistance": 0.0,
    }
    if pair is not None:
        costs["mj_geomDistance"] = _per_call_us(lambda: mujoco.mj_geomDistance(model, data, *pair, 0.1, fromto), 20000)
    return costs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clip", default="cmu_12_01_walk.bvh", help="a file name in ../shared/data")
    ap.add_argument("--character", default="humanoid", help="a bundled name or an MJCF path")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    path = DATA / args.clip
    if not path.exists():
        print(f"bench_floor: {path} not found (../shared/data is needed)", file=sys.stderr)
        return 2

    import daqp

    from physmocap.ik import qp as qp_module
    from physmocap.ik.config import RetargetConfig
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    from physmocap.errors import PhysmocapError

    try:
        motion = load_motion(path)
        character = load_character(args.character)
    except PhysmocapError as e:
        print(f"bench_floor: {e}", file=sys.stderr)
        return 2
    retarget(motion.slice_frames(0, min(30, motion.num_frames)), character, RetargetConfig(), progress=False)
    c0 = time.process_time()
    retarget(motion, character, RetargetConfig(), progress=False)
    fps = motion.num_frames / (time.process_time() - c0)

    captured = []
    solve = qp_module._solve

    def capturing(qp, dual_start=None):
        captured.append((qp_module._stack(qp), qp.H.copy(), qp.c.copy(), None if dual_start is None else dual_start.copy()))
        return solve(qp, dual_start)

    qp_module._solve = capturing
    profile = cProfile.Profile()
    try:
        profile.enable()
        retarget(motion, character, RetargetConfig(), progress=False)
        profile.disable()
    finally:
        qp_module._solve = solve
    n = len(captured)
    calls = {name: 0 for name in C_CALLS}
    for (_, _, name), row in pstats.Stats(profile).stats.items():  # type: ignore[attr-defined]
        if name.endswith(tuple(f"mujoco._functions.{c}>" for c in C_CALLS)):
            calls[name.rsplit(".", 1)[1].rstrip(">")] += row[1]
    costs = _c_costs(character)
    mujoco_us = sum(calls[c] / n * costs[c] for c in C_CALLS)
    t = time.perf_counter()
    for (A, upper, lower, sense), H, c, start in captured:
        daqp.solve(H, c, A, upper, lower, sense, dual_start=start)
    daqp_us = (time.perf_counter() - t) / n * 1e6
    per_frame_ms = (mujoco_us + daqp_us) * n / motion.num_frames / 1000.0
    print(f"{args.clip} onto {Path(args.character).stem}: {motion.num_frames} frames, {n} QPs "
          f"({n / motion.num_frames:.2f} per frame, every pass)")
    print("MuJoCo C calls per QP (the whole run's, over its QPs): " + ", ".join(f"{c} {calls[c] / n:.1f} x {costs[c]:.2f} us" for c in C_CALLS if calls[c]))
    print(f"per QP: MuJoCo {mujoco_us:.0f} us + daqp {daqp_us:.0f} us = {mujoco_us + daqp_us:.0f} us")
    print(f"floor: {per_frame_ms:.2f} ms per frame = {1000.0 / per_frame_ms:.0f} frames/s; "
          f"this run: {fps:.0f} frames/s CPU ({1000.0 / fps:.2f} ms per frame, "
          f"{100.0 * (1.0 - per_frame_ms * fps / 1000.0):.0f} % of it outside the floor)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
