"""The component-wise quaternion and vector products (``physmocap.rotations``): one vector
at a time (a stream's frame) takes Python floats, many take numpy views; both must give
numpy's own values bit for bit and numpy's broadcast shapes."""

import numpy as np
from hypothesis import given, settings, strategies as st

from physmocap.rotations import cross, quat_apply, quat_mul

# pairs of leading shapes that broadcast: single vectors in every shape, and stacks
SHAPES = [((), ()), ((1,), ()), ((), (1,)), ((1,), (1,)), ((1, 1), (1,)), ((5,), ()), ((), (5,)),
          ((1,), (5,)), ((1, 1), (5,)), ((5,), (5,)), ((2, 1), (1, 3)), ((1, 2, 1), (4,))]


def _quat_mul_reference(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=-1)


@settings(max_examples=60, deadline=None)
@given(pair=st.sampled_from(SHAPES), seed=st.integers(0, 2**31 - 1))
def test_small_products_match_numpy(pair, seed):
    rng = np.random.default_rng(seed)
    sa, sb = pair
    a3, b3 = rng.normal(size=(*sa, 3)), rng.normal(size=(*sb, 3))
    got, want = cross(a3, b3), np.cross(a3, b3)
    assert got.shape == want.shape and got.tobytes() == want.tobytes()
    q = rng.normal(size=(*sa, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    p = rng.normal(size=(*sb, 4))
    got, want = quat_mul(q, p), _quat_mul_reference(*np.broadcast_arrays(q, p))
    assert got.shape == want.shape and got.tobytes() == want.tobytes()
    # rotating a vector: the matrix's answer, in the broadcast shape
    v = quat_apply(q, b3)
    R = _matrix(q)
    assert v.shape == np.broadcast_shapes(q.shape[:-1], b3.shape[:-1]) + (3,)
    np.testing.assert_allclose(v, np.einsum("...ij,...j->...i", R, b3), atol=1e-12)
    # and the same bits whether it goes the one-vector way or numpy's (a stack of two)
    lead = np.broadcast_shapes(q.shape[:-1], b3.shape[:-1])
    qb, vb = np.broadcast_to(q, (*lead, 4))[..., None, :], np.broadcast_to(b3, (*lead, 3))[..., None, :]
    twice = quat_apply(np.concatenate([qb, qb], axis=-2), np.concatenate([vb, vb], axis=-2))[..., 0, :]
    assert twice.shape == v.shape and twice.tobytes() == v.tobytes()


def _matrix(q):
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def test_one_frame_kinematics_match_the_clips():
    """A stream's one-frame forward kinematics (joint by joint on floats) gives the clip's
    (depth by depth on arrays) bit for bit, translated joints included."""
    from physmocap.motion import forward_kinematics
    from physmocap.resources import example_clip
    from physmocap.sources import load_motion

    m = load_motion(example_clip())
    rng = np.random.default_rng(3)
    rot = m.rotations[:40] * rng.uniform(0.5, 1.5, size=(40, 1, 1))  # not unit: the same products still
    P, W = forward_kinematics(m.skeleton, rot, m.translations[:40], m.translated)
    for t in range(40):
        p, w = forward_kinematics(m.skeleton, rot[t : t + 1], m.translations[t : t + 1], m.translated)
        assert p.tobytes() == P[t : t + 1].tobytes() and w.tobytes() == W[t : t + 1].tobytes()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), scale=st.sampled_from([1e-12, 1e-7, 1e-3, 1.0, 3.1]))
def test_rotation_vectors_match_scipy(seed, scale):
    """quat_from_rotvec / quat_to_rotvec give scipy's answers to round-off, tiny angles,
    angles near pi and a negative scalar part included."""
    from scipy.spatial.transform import Rotation

    from physmocap.rotations import quat_from_rotvec, quat_to_rotvec

    rng = np.random.default_rng(seed)
    v = rng.normal(size=(20, 3))
    v *= scale / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0.5, 1.0, size=(20, 1))
    np.testing.assert_allclose(quat_from_rotvec(v), Rotation.from_rotvec(v).as_quat(), atol=1e-14)
    q = rng.normal(size=(20, 4))
    q[:5, :3] *= scale  # near the identity, both signs of w
    q[5:10, 3] = -np.abs(q[5:10, 3])
    np.testing.assert_allclose(quat_to_rotvec(q), Rotation.from_quat(q).as_rotvec(), atol=1e-12)
    assert quat_from_rotvec(v[0]).shape == (4,) and quat_to_rotvec(q[0]).shape == (3,)
