"""Attitude conventions and conversions (closed forms and round trips)."""

import numpy as np

from leosop import rotations as rot


def test_euler_convention_closed_forms():
    forward, right = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    # Pitch up 30 deg: the nose rises.
    np.testing.assert_allclose(rot.euler_to_dcm(np.radians(30), 0, 0) @ forward, [0, np.cos(np.pi / 6), 0.5],
                               atol=1e-15)
    # Roll 30 deg right wing down.
    np.testing.assert_allclose(rot.euler_to_dcm(0, np.radians(30), 0) @ right, [np.cos(np.pi / 6), 0, -0.5], atol=1e-15)
    # Yaw +90 (counter-clockwise) points the nose West: heading 270 deg.
    np.testing.assert_allclose(rot.euler_to_dcm(0, 0, np.pi / 2) @ forward, [-1, 0, 0], atol=1e-15)
    assert np.degrees(rot.heading_from_yaw(np.pi / 2)) == 270.0


def test_round_trips():
    rng = np.random.default_rng(4)
    p, r, y = rng.uniform(-1.5, 1.5, 500), rng.uniform(-3.1, 3.1, 500), rng.uniform(-3.1, 3.1, 500)
    C = rot.euler_to_dcm(p, r, y)
    for a, b in zip(rot.dcm_to_euler(C), (p, r, y)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(rot.quat_to_dcm(rot.dcm_to_quat(C)), C, atol=1e-14)
    np.testing.assert_allclose(rot.yaw_from_heading(rot.heading_from_yaw(y)), y, atol=1e-12)


def test_rotation_vector_quaternion_and_product():
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(100, 3)), rng.normal(size=(100, 3)) * 1e-9
    for phi in (a, b):
        np.testing.assert_allclose(rot.quat_to_dcm(rot.rotvec_to_quat(phi)), rot.rotvec_to_dcm(phi), atol=1e-14)
    qa, qb = rot.rotvec_to_quat(a), rot.rotvec_to_quat(a[::-1])
    np.testing.assert_allclose(rot.quat_to_dcm(rot.quat_multiply(qa, qb)),
                               rot.quat_to_dcm(qa) @ rot.quat_to_dcm(qb), atol=1e-14)
    # Rodrigues on the axis: a rotation vector is invariant under its own rotation.
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rot.rotvec_to_dcm(a), a), a, atol=1e-12)
    np.testing.assert_allclose(rot.skew(a) @ b[..., None], np.cross(a, b)[..., None], atol=1e-20)


def test_stack_last_is_nested_np_stack_to_the_last_bit():
    """The small matrices of a filter step (``skew``, ``quat_to_dcm``) are made by ``shapes.stack_last``: the
    values and C-contiguous layout of ``np.stack`` of ``np.stack``, for one matrix and for a batch."""
    from leosop.shapes import stack_last

    rng = np.random.default_rng(3)
    for shape in ((), (4, 5)):
        e = [[rng.normal(size=shape) for _ in range(3)] for _ in range(2)]
        want = np.stack([np.stack(r, axis=-1) for r in e], axis=-2)
        got = stack_last(e, 2)
        assert got.shape == shape + (2, 3) and got.flags.c_contiguous and np.array_equal(got, want)
        assert np.array_equal(stack_last(e[0]), np.stack(e[0], axis=-1))
