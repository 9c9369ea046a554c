"""Property tests of pbdkit._rotations: the conversions invert each other, q and -q are one
rotation, exp and log are inverse within the principal range, the left Jacobian is the
derivative of the exponential map (finite differences), and the control-loop paths equal the
batched ones."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pbdkit._rotations import (
    exp_map,
    left_jacobian,
    left_jacobian_inverse,
    left_jacobian_inverse3,
    log3,
    log_map,
    matrix_from_quaternion,
    quaternion_from_matrix,
    skew,
)

from .strategies import DETERMINISTIC, quaternions, rotation_vectors, seeds

# Central differences of step H: truncation ~H^2, rounding ~eps / H, both below 1e-9.
H = 1e-6


def _is_rotation(rot: np.ndarray) -> None:
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), rtol=0, atol=1e-14)
    assert abs(np.linalg.det(rot) - 1.0) < 1e-14


@settings(DETERMINISTIC, max_examples=100)
@given(q=quaternions())
def test_quaternion_matrix_quaternion_round_trip(q: np.ndarray) -> None:
    rot = matrix_from_quaternion(q)
    _is_rotation(rot)
    back = quaternion_from_matrix(rot)
    unit = q / np.linalg.norm(q)
    # The same unit quaternion, with w >= 0 (of the two that give the rotation).
    assert back[0] >= 0.0
    np.testing.assert_allclose(abs(back @ unit), 1.0, rtol=0, atol=1e-14)
    if abs(unit[0]) > 1e-8:
        np.testing.assert_allclose(back, np.sign(unit[0]) * unit, rtol=0, atol=1e-14)
    np.testing.assert_allclose(matrix_from_quaternion(back), rot, rtol=0, atol=1e-14)


@settings(DETERMINISTIC, max_examples=100)
@given(q=quaternions())
def test_q_and_minus_q_are_the_same_rotation(q: np.ndarray) -> None:
    # Exactly: every entry is a product of two components, or a sum of such.
    np.testing.assert_array_equal(matrix_from_quaternion(-q), matrix_from_quaternion(q))


@settings(DETERMINISTIC, max_examples=150)
@given(r=rotation_vectors())
def test_rotation_vector_quaternion_and_matrix_agree(r: np.ndarray) -> None:
    # The quaternion of exp([r]x) is (cos(t/2), sin(t/2) r / t): the closed form, independently.
    t = float(np.linalg.norm(r))
    half = np.sinc(t / (2.0 * np.pi)) / 2.0  # sin(t/2) / t, exact at t = 0
    expected = np.concatenate([[np.cos(t / 2.0)], half * r])
    rot = exp_map(r)
    _is_rotation(rot)
    np.testing.assert_allclose(quaternion_from_matrix(rot), expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(matrix_from_quaternion(expected), rot, rtol=0, atol=1e-14)


@settings(DETERMINISTIC, max_examples=150)
@given(r=rotation_vectors())
def test_log_inverts_exp_within_the_principal_range(r: np.ndarray) -> None:
    # Angles in [0, pi - 1e-6]: the rotation vector comes back, at 1e-6 rad from pi too.
    np.testing.assert_allclose(log_map(exp_map(r)), r, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log3(exp_map(r)), r, rtol=0, atol=1e-10)


@settings(DETERMINISTIC, max_examples=100)
@given(q=quaternions())
def test_exp_inverts_log_and_log_is_in_the_principal_range(q: np.ndarray) -> None:
    rot = matrix_from_quaternion(q)
    r = log_map(rot)
    assert np.linalg.norm(r) <= np.pi + 1e-12
    np.testing.assert_allclose(exp_map(r), rot, rtol=0, atol=1e-13)
    # The control-loop log3 is the same map, up to its formulas' rounding (and the sign of r
    # at exactly pi, where r and -r are one rotation).
    np.testing.assert_allclose(exp_map(log3(rot)), rot, rtol=0, atol=1e-10)


@settings(DETERMINISTIC, max_examples=100)
@given(r=rotation_vectors(max_angle=np.pi - 0.05))
def test_left_jacobian_is_the_derivative_of_exp(r: np.ndarray) -> None:
    # exp([r + dr]x) exp([r]x)^T = exp([J_l(r) dr]x) to first order: column i of J_l is the
    # derivative of log(exp([r + h e_i]x) exp([r]x)^T) at h = 0.
    rot_t = exp_map(r).T
    steps = H * np.eye(3)
    fd = (log_map(exp_map(r + steps) @ rot_t) - log_map(exp_map(r - steps) @ rot_t)) / (2 * H)
    np.testing.assert_allclose(left_jacobian(r), fd.T, rtol=0, atol=1e-8)


@settings(DETERMINISTIC, max_examples=100)
@given(r=rotation_vectors(max_angle=np.pi - 0.05))
def test_left_jacobian_inverse_is_the_inverse(r: np.ndarray) -> None:
    j = left_jacobian(r)
    j_inv = left_jacobian_inverse(r)
    # J_l's (1 - cos t) / t^2 cancels just above its series (t = 1e-6): about 1e-16 / t of
    # error, 1e-10 there (measured 4.3e-11), 1e-13 from t = 1e-3 up.
    np.testing.assert_allclose(j @ j_inv, np.eye(3), rtol=0, atol=2e-10)
    # The rotation axis is fixed: J_l(r) r = r; and J_l(-r) = J_l(r)^T.
    np.testing.assert_allclose(j @ r, r, rtol=0, atol=1e-14)
    np.testing.assert_allclose(left_jacobian(-r), j.T, rtol=0, atol=1e-15)
    # The control-loop path equals the batched one.
    np.testing.assert_allclose(left_jacobian_inverse3(r), j_inv, rtol=0, atol=1e-12)


@settings(DETERMINISTIC, max_examples=50)
@given(seed=seeds, batch=st.integers(1, 4))
def test_skew_is_the_cross_product_and_batches(seed: int, batch: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, batch, 3))
    np.testing.assert_allclose(
        np.einsum("bij,bj->bi", skew(a), b), np.cross(a, b), rtol=0, atol=1e-14
    )
    np.testing.assert_array_equal(skew(a), np.stack([skew(v) for v in a]))
