"""The lean QP assembly (physmocap.ik.qp) builds mink.build_ik's problem, so it cannot drift.

On a few configurations of both bundled characters (feet near the floor, limbs
close, a previous frame for the step limits, planted contacts), the builder's
``H``, ``c``, simple bounds, general rows and equalities are compared with
``mink.build_ik`` over the same tasks and limits, whose plus/minus identity rows
(joint ranges, frame-to-frame step, root step) are folded into bounds here, and
both QPs' solutions are compared.
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np
import pytest
import qpsolvers

from physmocap.ik.qp import INFINITY, solve
from physmocap.ik.solver import ContactHolds, FrameSolver
from physmocap.ik.tasks import SitePositionTask
from physmocap.models import load_character


def _fold(G: np.ndarray, h: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Bounds ``(lb, ub)`` equivalent to rows ``G x <= h`` that are each +/- a unit vector."""
    lb, ub = np.full(nv, -INFINITY), np.full(nv, INFINITY)
    for g, hk in zip(G, h):
        (j,) = np.flatnonzero(g)
        if g[j] > 0:
            ub[j] = min(ub[j], hk / g[j])
        else:
            lb[j] = max(lb[j], hk / g[j])
    return lb, ub


def _setup(name: str, seed: int):
    ch = load_character(name)
    model = ch.model
    rng = np.random.default_rng(seed)
    names = list(ch.tracked)
    oriented = np.arange(len(names)) % 3 == 0
    solver = FrameSolver(ch, names, oriented, fps=120.0)
    q = np.array(ch.rest_qpos, dtype=float)
    lim = model.jnt_limited.astype(bool) & (model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
    adr = model.jnt_qposadr[lim]
    lo, hi = model.jnt_range[lim].T
    q[adr] = np.clip(q[adr] + rng.normal(0.0, 0.3, len(adr)), lo + 0.01, hi - 0.01)
    solver.reset(q)
    data = solver.configuration.data
    # lower the body until its lowest geom point is 1 cm above the floor (floor rows active)
    z, _, _ = solver.floor_limit.heights(data)
    q[2] -= float(z.min()) - 0.01
    solver.reset(q)
    q_prev = q.copy()
    q_prev[adr] += rng.uniform(-0.01, 0.01, len(adr))
    solver.q_prev = q_prev
    solver.step_limit.set_previous(q_prev)
    solver.root_limit.set_previous(q_prev)
    # targets near the current sites, some off
    pos = np.array([_frame_pos(ch, data, n) for n in names])
    pos += rng.normal(0.0, 0.03, pos.shape)
    quat = rng.normal(size=(len(names), 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    valid = rng.random(len(names)) > 0.1
    solver._set_targets(pos, quat, valid)
    # planted contacts: one site held in all axes, one in height only, one soft pull
    sites = [s for side in ch.contacts.values() for s in side]
    hard = []
    for s, axes in zip(sites[:2], [(0, 1, 2), (2,)]):
        t = SitePositionTask(model, s, cost=1.0, axes=axes)
        t.set_target(data.site_xpos[model.site(s).id] + rng.normal(0.0, 0.005, 3))
        hard.append(t)
    soft = SitePositionTask(model, sites[-1], cost=[3.0, 3.0, 10.0])
    soft.set_target(data.site_xpos[model.site(sites[-1]).id] - [0.0, 0.0, 0.01])
    holds = ContactHolds((soft,), tuple(hard), {model.site(sites[-1]).id: 0.012}, {})
    solver._set_holds(holds)
    return solver


def _frame_pos(ch, data, name):
    tf = ch.tracked[name]
    m = ch.model
    if tf.kind == "site":
        return data.site_xpos[m.site(tf.name).id].copy()
    return data.xpos[m.body(tf.name).id].copy()


@pytest.mark.parametrize("name,seed", [("humanoid", 0), ("humanoid", 1), ("robot", 2), ("robot", 3)])
@pytest.mark.parametrize("level", [0, 1, 2, 3, 4])
def test_lean_qp_matches_mink_build_ik(name, seed, level):
    solver = _setup(name, seed)
    conf = solver.configuration
    nv = solver.model.nv
    solver._sync()
    boxes, general = solver._limits(level)
    # the ladder as FrameSolver._limits has it (unchanged by the lean path): the frame-to-frame
    # bound is kept up to level 2, the floor and self-collision rows up to level 3
    assert solver.self_limit is None or (solver.self_limit in general) == (level <= 3)
    assert (solver.step_limit in boxes) == (level <= 2)
    # what the lean path builds
    tasks = [*solver.tasks, *solver._extra_tasks] + (list(solver._constraints) if level >= 1 else [])
    constraints = solver._constraints if level == 0 else []
    qp = solver._builder.build(conf, tasks, 1e-4, posture=(solver.posture,), trust=solver._trust,
                               config_limit=solver.config_limit, boxes=boxes, limits=general, constraints=constraints)
    H, c, lb, ub = qp.H.copy(), qp.c.copy(), qp.lb.copy(), qp.ub.copy()
    G, h, A, b = qp.G.copy(), qp.h.copy(), qp.A.copy(), qp.b.copy()
    # what mink builds: same tasks (posture as a task), every limit as rows
    mink_tasks = [*solver.tasks, solver.posture, *solver._extra_tasks] + (list(solver._constraints) if level >= 1 else [])
    box_limits = [solver.config_limit, *boxes]
    ref = mink.build_ik(conf, mink_tasks, 1.0, damping=1e-4, limits=box_limits + general,
                        constraints=constraints or None)
    scale = np.abs(ref.P).max()
    np.testing.assert_allclose(H, ref.P, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(c, ref.q, rtol=0, atol=1e-12 * max(1.0, np.abs(ref.q).max()))
    nbox = sum(0 if lim.compute_qp_inequalities(conf, 1.0).inactive else len(lim.compute_qp_inequalities(conf, 1.0).h)
               for lim in box_limits)
    flb, fub = _fold(ref.G[:nbox], ref.h[:nbox], nv)
    np.testing.assert_array_equal(lb, np.maximum(flb, -solver._trust))
    np.testing.assert_array_equal(ub, np.minimum(fub, solver._trust))
    np.testing.assert_allclose(G, ref.G[nbox:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(h, ref.h[nbox:], rtol=0, atol=1e-15)
    if level <= 3:
        assert len(h) > 0  # floor rows active
    else:
        assert len(h) == 0 and general == []
    if level == 0:
        np.testing.assert_array_equal(A, ref.A)
        np.testing.assert_array_equal(b, ref.b)
        assert len(b) == 4
    else:
        assert ref.A is None and len(b) == 0
    # and the same solution as mink's problem through qpsolvers (trust region as bounds)
    ref.lb, ref.ub = -solver._trust, solver._trust
    try:
        x_ref = qpsolvers.solve_problem(ref, solver="daqp").x
    except Exception:  # pragma: no cover
        x_ref = None
    try:
        x = solve(qp)
    except mink.NoSolutionFound:
        x = None
    if x_ref is None:
        assert x is None
    else:
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-9)


def _floor_rows_reference(limit, data):
    """The floor rows point by point (one mj_jac each), as the limit first wrote them."""
    z, anchor, body = limit.heights(data)
    G, h = [], []
    jac = np.zeros((3, limit.model.nv))
    for k in np.flatnonzero(z < limit.floor + limit.activation):
        mujoco.mj_jac(limit.model, data, jac, None, anchor[k], int(body[k]))
        G.append(-jac[2].copy())
        c = limit.swing_bodies.get(int(body[k]))
        h.append(z[k] - limit.floor - limit.margin if c is None else z[k] - min(limit.floor + max(c, limit.margin), z[k] + limit.max_rise))
    for sid, c in limit.clearance.items():
        zs = data.site_xpos[sid, 2]
        mujoco.mj_jacSite(limit.model, data, jac, None, sid)
        G.append(-jac[2].copy())
        h.append(zs - min(limit.floor + c, zs + limit.max_rise))
    return np.array(G), np.array(h)


def _self_rows_reference(limit, data):
    """The self-collision rows pair by pair, as the limit first wrote them."""
    model = limit.model
    ja, jb, fromto = np.zeros((3, model.nv)), np.zeros((3, model.nv)), np.zeros(6)
    G, h = [], []
    for k in limit.near_pairs(data):
        g1, g2 = (int(x) for x in limit.pairs[k])
        d = mujoco.mj_geomDistance(model, data, g1, g2, limit.activation, fromto)
        if d >= limit.activation:
            continue
        pa, pb = fromto[:3].copy(), fromto[3:].copy()
        n = pb - pa
        n /= np.linalg.norm(n)
        if d < 0:
            n = -n
        mujoco.mj_jac(model, data, ja, None, pa, int(model.geom_bodyid[g1]))
        mujoco.mj_jac(model, data, jb, None, pb, int(model.geom_bodyid[g2]))
        G.append(-(n @ (jb - ja)))
        h.append(d - limit.margin if d >= limit.margin else -min(limit.margin - d, limit.recovery))
    return np.array(G).reshape(-1, model.nv), np.array(h)


@pytest.mark.parametrize("name,seed", [("humanoid", 0), ("robot", 2)])
def test_floor_and_self_collision_rows_match_point_by_point(name, seed):
    solver = _setup(name, seed)
    data = solver.configuration.data
    solver._sync()
    body = int(solver.model.site_bodyid[solver.model.site(solver.character.contacts["left"][0]).id])
    solver.floor_limit.swing_bodies = {body: 0.012}
    con = solver.floor_limit.compute_qp_inequalities(solver.configuration, 1.0)
    G, h = _floor_rows_reference(solver.floor_limit, data)
    np.testing.assert_allclose(con.G, G, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(con.h, h)
    # bring two limbs close: the self-collision rows, pair by pair
    limit = solver.self_limit
    assert limit is not None
    for q in np.linspace(0.0, 1.0, 6):
        qpos = solver.configuration.q
        qpos[7:] *= 1.0 - 0.1 * q
        solver.reset(qpos)
        solver._first = False
        con = limit.compute_qp_inequalities(solver.configuration, 1.0)
        G, h = _self_rows_reference(limit, data)
        if con.inactive:
            assert len(h) == 0
        else:
            np.testing.assert_allclose(con.G, G, rtol=0, atol=1e-12)
            np.testing.assert_allclose(con.h, h, rtol=0, atol=1e-15)


def test_floor_rows_follow_the_frames_clearances_and_the_pose():
    """The floor limit keeps what its rows read apart from the pose per set of active points
    and frame's clearances: new clearances (a new frame) and a new pose give the same rows,
    to the bit, as a limit that kept nothing."""
    from physmocap.ik.limits import FloorLimit

    solver = _setup("humanoid", 0)
    solver._sync()
    model, limit = solver.model, solver.floor_limit
    fresh = FloorLimit(model, sites=limit.sites, floor=limit.floor, margin=limit.margin, activation=limit.activation)
    z, _, body = limit.heights(solver.configuration.data)
    foot = int(body[np.flatnonzero(z < limit.floor + limit.activation)[0]])  # a body with points near the floor
    toe = int(limit.sites[-1])
    frames = [({}, {}), ({}, {foot: 0.012}), ({toe: 0.02}, {foot: 0.012}), ({toe: 0.02}, {})]
    for step, (clearance, bodies) in enumerate([*frames, *frames]):
        if step == len(frames):  # the same frames again in another pose
            qpos = solver.configuration.q
            qpos[2] -= 0.01
            solver.reset(qpos)
        for lim in (limit, fresh):
            lim.clearance, lim.swing_bodies = dict(clearance), dict(bodies)
        fresh._plan = (None, None, None)
        kept = limit.compute_qp_inequalities(solver.configuration, 1.0)
        again = limit.compute_qp_inequalities(solver.configuration, 1.0)
        new = fresh.compute_qp_inequalities(solver.configuration, 1.0)
        for con in (kept, again):
            assert con.G.tobytes() == new.G.tobytes() and con.h.tobytes() == new.h.tobytes()


def test_bounds_index_consecutive_dofs_by_slice():
    """Consecutive dofs (every hinge of the bundled characters, the free root) are written
    through slices, any other index set through fancy indexing: the same bounds either way."""
    from physmocap.ik.qp import _span, _tighten

    assert _span(np.arange(6, 50)) == slice(6, 50)
    idx = np.array([1, 2, 4])
    assert _span(idx) is not None and not isinstance(_span(idx), slice)
    rng = np.random.default_rng(0)
    lb0, ub0 = -rng.random(12), rng.random(12)
    lo, hi = -rng.random(5), rng.random(5)
    for dofs in (np.arange(3, 8), np.array([0, 2, 3, 7, 11])):
        lb, ub = lb0.copy(), ub0.copy()
        _tighten(lb, ub, _span(dofs), lo, hi)
        lb_ref, ub_ref = lb0.copy(), ub0.copy()
        lb_ref[dofs] = np.maximum(lb_ref[dofs], lo)
        ub_ref[dofs] = np.minimum(ub_ref[dofs], hi)
        np.testing.assert_array_equal(lb, lb_ref)
        np.testing.assert_array_equal(ub, ub_ref)


def test_frame_tasks_targets_and_costs_are_read_once_per_frame():
    """The builder reads the frame tasks' targets, costs and gains at the first QP after
    ``new_frame`` (the solver's ``_set_holds``), so a target that comes or goes between
    frames changes the next frame's QP exactly as mink's own build does."""
    solver = _setup("humanoid", 0)
    conf = solver.configuration
    solver._sync()
    tasks = [*solver.tasks, *solver._extra_tasks]
    before = solver._builder.objective(conf, tasks, 1e-4)[1].copy()
    _, task, pc, oc = solver.frame_tasks[0]
    task.set_position_cost(0.0)
    task.set_orientation_cost(0.0)
    solver._set_holds(ContactHolds(tuple(solver._extra_tasks), tuple(solver._constraints)))
    H, c = solver._builder.objective(conf, tasks, 1e-4)
    ref = mink.build_ik(conf, tasks, 1.0, damping=1e-4)
    assert not np.array_equal(c, before)
    np.testing.assert_allclose(H, ref.P, rtol=0, atol=1e-12 * np.abs(ref.P).max())
    np.testing.assert_allclose(c, ref.q, rtol=0, atol=1e-12 * max(1.0, np.abs(ref.q).max()))
