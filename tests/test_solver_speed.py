"""The IK's shortcuts give the figures of the long way round.

* :meth:`FloorLimit.near` evaluates only the candidates of the geoms near the floor:
  its heights are :meth:`FloorLimit.heights`'s, and the points it leaves out are
  above the activation band.
* :meth:`PointJacobians.vertical` (the floor rows' Jacobians, all points at once) gives
  ``mj_jac``'s vertical rows, negated, to the bit.
* The second-order correction (``SolverOptions.second_order_correction``) of a full
  step leaves the planted contacts far closer to their anchors than the step itself,
  and is off by default.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physmocap.ik.limits import PointJacobians
from physmocap.ik.solver import ContactHolds, SolverOptions
from physmocap.models import load_character
from conftest import RETARGET_DIAGNOSTICS, shared_file
from test_qp import _setup


@pytest.mark.parametrize("name,seed", [("humanoid", 0), ("humanoid", 3), ("robot", 2)])
def test_floor_near_points_are_the_heights_within_reach(name, seed):
    solver = _setup(name, seed)
    limit, data = solver.floor_limit, solver.configuration.data
    rng = np.random.default_rng(seed)
    q0 = solver.configuration.q
    for drop in (0.0, 0.05, 0.3):
        q = q0.copy()
        q[2] += drop
        q[7:] += rng.normal(0.0, 0.05, len(q) - 7)
        solver.reset(q)
        z_all, _, _ = limit.heights(data)
        idx, z_near = limit.near(data)
        np.testing.assert_array_equal(z_near, z_all[idx])
        assert np.all(np.diff(idx) > 0)
        left_out = np.setdiff1d(np.arange(len(z_all)), idx)
        assert np.all(z_all[left_out] == np.inf)
        np.testing.assert_array_equal(limit.z(data), z_all)
        assert limit.lowest(data) == (z_all.min() if np.isfinite(z_all).any() else np.inf)


@pytest.mark.parametrize("name,seed", [("humanoid", 0), ("robot", 1)])
def test_vertical_point_jacobians_are_mj_jac_rows_to_the_bit(name, seed):
    model = load_character(name).model
    data = mujoco.MjData(model)
    rng = np.random.default_rng(seed)
    jacobians = PointJacobians(model)
    k = 40  # beyond the buffers' first capacity; the world body included
    for _ in range(5):
        data.qpos[:] = model.qpos0 + rng.normal(0.0, 0.5, model.nq)
        mujoco.mj_normalizeQuat(model, data.qpos)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        bodies = rng.integers(0, model.nbody, k)
        points = data.xpos[bodies] + rng.normal(0.0, 0.1, (k, 3))
        out = np.empty((k, model.nv))
        jacobians.vertical(data, bodies, points, out)
        assert out.tobytes() == (-jacobians(data, bodies, points)[:, 2]).tobytes()


def test_second_order_correction_is_off_by_default():
    assert SolverOptions().second_order_correction is False
    solver = _setup("humanoid", 0)
    solver._step(0)
    assert solver._qp is None


@pytest.mark.parametrize("name,seed", [("humanoid", 0), ("humanoid", 1), ("robot", 2)])
def test_second_order_correction_removes_the_contacts_second_order_error(name, seed):
    solver = _setup(name, seed)
    for _ in range(8):  # near the frame's solution first: a step of the size frames take
        solver._line_search(solver._step(0))
    rng = np.random.default_rng(seed)
    for task in solver._constraints:  # the planted contacts move by a few millimetres
        task.set_target(task.target + rng.normal(0.0, 0.003, 3))
    limit = solver.floor_limit
    solver._set_holds(ContactHolds(tuple(solver._extra_tasks), tuple(solver._constraints), limit.clearance, limit.swing_bodies))
    solver.options.second_order_correction = True
    solver._sync()
    v = solver._step(0)
    qp, q0, e0 = solver._qp, solver.configuration.q, solver._contact_errors()
    assert qp is not None and e0 is not None
    solver._integrate(v, 1.0)
    full = solver._contact_residual()
    # from the full step's pose, as the line search calls it; any residual accepted: only
    # the correction's effect is measured
    assert solver._corrected(qp, v, q0, e0, np.inf)
    corrected = solver._contact_residual()
    assert full > 1e-6  # the full step's linearisation error is there to remove
    assert corrected < 0.05 * full
    assert np.all(np.isfinite(solver.configuration.q))



@RETARGET_DIAGNOSTICS
def test_extrapolated_start_is_off_by_default_and_keeps_the_constraints():
    """``extrapolate_start``: off by default; on, frames start from the constant-velocity
    prediction once two frames converged, take fewer iterations on a walk, track it as well
    and hold every hard constraint."""
    from physmocap import metrics
    from physmocap.ik.retarget import retarget
    from physmocap.models import load_character
    from physmocap.sources import load_motion

    assert SolverOptions().extrapolate_start is False
    motion = load_motion(shared_file("cmu_12_01_walk.bvh")).slice_frames(0, 240)
    ch = load_character("humanoid")
    # one pass: the last pass (ik/transitions.py) starts every frame from the first pass's pose
    runs = [retarget(motion, ch, progress=False, extrapolate_start=on, smooth_transitions=False) for on in (False, True)]
    off, on = runs
    assert np.mean(on.solver.iterations) < 0.9 * np.mean(off.solver.iterations)
    assert metrics.tracking_errors(on)["all_mean_cm"] < 1.05 * metrics.tracking_errors(off)["all_mean_cm"]
    assert metrics.joint_limit_violations(ch.model, on.qpos)["count"] == 0
    assert metrics.penetration(ch.model, on.qpos)["max_mm"] <= 1.0
    assert not np.count_nonzero(on.solver.relaxation)
    # the start changes the answers, not the problem: the two stay close
    assert np.abs(on.qpos[:, 7:] - off.qpos[:, 7:]).mean() < 0.02
