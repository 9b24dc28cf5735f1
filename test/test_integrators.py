"""Fixed-step Runge–Kutta integrators and quaternion orientation kinematics."""

import itertools

import numpy as np
import pytest

from grasp_safety_filter.model.quaternion import (
    from_rotation_matrix,
    normalized,
    quaternion_derivative,
    rotation_matrix,
)
from hand_sim_node.integrators import ButcherTableau, integrator, INTEGRATORS, ODE3, RK4

TABLEAUX = [ODE3, RK4]


def integrate(tableau, f, x0, t_end, dt):
    x, t = np.array(x0, dtype=float), 0.0
    n = round(t_end / dt)
    for k in range(n):
        x = tableau.step(f, t, x, dt)
        t = (k + 1) * dt
    return x


def skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rodrigues(rotation_vector):
    angle = np.linalg.norm(rotation_vector)
    if angle == 0.0:
        return np.eye(3)
    K = skew(rotation_vector / angle)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


# Analytic test problems: (name, f, x0, exact solution at t = 1).
PROBLEMS = [
    ('logistic', lambda t, x: x * (1.0 - x), [0.2], [1.0 / (1.0 + 4.0 * np.exp(-1.0))]),
    ('time-varying decay', lambda t, x: -2.0 * t * x, [1.0], [np.exp(-1.0)]),
    (
        'oscillator',
        lambda t, x: np.array([x[1], -4.0 * x[0]]),
        [1.0, 0.0],
        [np.cos(2.0), -2.0 * np.sin(2.0)],
    ),
]


# ------------------------------------------------------------------------------ tableaux
def order_conditions(tableau):
    """Classical order conditions up to order 4 (Butcher trees), left - right."""
    a, b, c = tableau.a, tableau.b, tableau.c
    conditions = {
        1: [b.sum() - 1.0],
        2: [b @ c - 1.0 / 2.0],
        3: [b @ c**2 - 1.0 / 3.0, b @ (a @ c) - 1.0 / 6.0],
        4: [
            b @ c**3 - 1.0 / 4.0,
            b @ (c * (a @ c)) - 1.0 / 8.0,
            b @ (a @ c**2) - 1.0 / 12.0,
            b @ (a @ (a @ c)) - 1.0 / 24.0,
        ],
    }
    return conditions


@pytest.mark.parametrize('tableau', TABLEAUX, ids=lambda t: t.name)
def test_tableau_satisfies_exactly_the_order_conditions_of_its_order(tableau):
    conditions = order_conditions(tableau)
    for order in range(1, tableau.order + 1):
        np.testing.assert_allclose(conditions[order], 0.0, atol=1e-15)
    if tableau.order < 4:
        assert np.max(np.abs(conditions[tableau.order + 1])) > 1e-3


def test_ode3_is_bogacki_shampine_as_in_matlab():
    # Matlab's ode3: k1 = f(t, y); k2 = f(t + h/2, y + h/2 k1); k3 = f(t + 3h/4, y + 3h/4 k2);
    # y + h (2 k1 + 3 k2 + 4 k3) / 9.
    def f(t, y):
        return np.array([np.sin(t) * y[0] - y[1] ** 2, t * y[0]])

    t, y, h = 0.3, np.array([0.7, -0.2]), 0.05
    k1 = f(t, y)
    k2 = f(t + h / 2, y + h / 2 * k1)
    k3 = f(t + 3 * h / 4, y + 3 * h / 4 * k2)
    expected = y + h * (2 * k1 + 3 * k2 + 4 * k3) / 9
    np.testing.assert_allclose(ODE3.step(f, t, y, h), expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize('tableau', TABLEAUX, ids=lambda t: t.name)
def test_quadrature_of_polynomial_of_degree_order_minus_one_is_exact(tableau):
    degree = tableau.order - 1

    def f(t, x):
        return np.array([(degree + 1) * t**degree])

    # x(t) = t^(degree+1): an order-p method integrates x' = t^(p-1) without error.
    x = integrate(tableau, f, [0.0], 1.0, 0.125)
    np.testing.assert_allclose(x, [1.0], atol=1e-14)


@pytest.mark.parametrize('tableau', TABLEAUX, ids=lambda t: t.name)
@pytest.mark.parametrize('name, f, x0, exact', PROBLEMS, ids=[p[0] for p in PROBLEMS])
def test_halving_the_step_divides_the_error_by_two_to_the_order(tableau, name, f, x0, exact):
    errors = [
        np.linalg.norm(integrate(tableau, f, x0, 1.0, dt) - np.array(exact))
        for dt in (0.02, 0.01, 0.005)
    ]
    expected_ratio = 2.0**tableau.order
    for coarse, fine in itertools.pairwise(errors):
        assert 0.8 * expected_ratio < coarse / fine < 1.25 * expected_ratio, errors


@pytest.mark.parametrize('tableau', TABLEAUX, ids=lambda t: t.name)
def test_given_first_stage_is_used_instead_of_a_new_evaluation(tableau):
    calls = []

    def f(t, x):
        calls.append(t)
        return -x + np.cos(t)

    x0 = np.array([0.4, -1.0])
    full = tableau.step(f, 0.2, x0, 0.01)
    assert len(calls) == tableau.n_stages
    calls.clear()
    reused = tableau.step(f, 0.2, x0, 0.01, k1=f(0.2, x0))
    assert len(calls) == tableau.n_stages  # one here + (s - 1) inside
    np.testing.assert_array_equal(full, reused)


def test_integrator_lookup_and_validation():
    assert integrator('ode3') is ODE3 and integrator('rk4') is RK4
    assert set(INTEGRATORS) == {'ode3', 'rk4'}
    message = r"integrator: expected one of \['ode3', 'rk4'\], got 'rk45'"
    with pytest.raises(ValueError, match=message):
        integrator('rk45')
    with pytest.raises(ValueError, match='strictly lower-triangular'):
        ButcherTableau('implicit', 1, np.array([[1.0]]), np.array([1.0]), np.array([1.0]))
    with pytest.raises(ValueError, match='sum'):
        ButcherTableau('bad', 1, np.zeros((2, 2)), np.array([0.5, 0.4]), np.zeros(2))


# ---------------------------------------------------------------------------- quaternions
def random_rotations(count, seed=0):
    rng = np.random.default_rng(seed)
    rotations = [rodrigues(v) for v in rng.normal(size=(count, 3))]
    # Near-half-turns exercise the non-trace pivots.
    rotations += [rodrigues(np.pi * axis / np.linalg.norm(axis)) for axis in np.eye(3)]
    rotations.append(rodrigues(np.array([0.0, 0.0, np.pi - 1e-9])))
    return rotations


def test_rotation_matrix_round_trip_and_orthonormality():
    for R in random_rotations(20):
        quaternion = from_rotation_matrix(R)
        assert quaternion[3] >= 0.0
        np.testing.assert_allclose(np.linalg.norm(quaternion), 1.0, atol=1e-14)
        np.testing.assert_allclose(rotation_matrix(quaternion), R, atol=1e-12)
    R = rotation_matrix(np.array([0.3, -1.2, 0.5, 2.0]))  # not unit: normalised first
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


def test_rotation_about_z_by_a_quarter_turn():
    quaternion = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    np.testing.assert_allclose(
        rotation_matrix(quaternion) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15
    )


def test_quaternion_rate_gives_spatial_angular_velocity():
    # R_dot = [w]x R with w in palm coordinates, by central differences of R(quat + h quat_dot).
    rng = np.random.default_rng(1)
    for R in random_rotations(5, seed=2):
        quaternion = from_rotation_matrix(R)
        omega = rng.normal(size=3)
        rate = quaternion_derivative(quaternion, omega)
        assert abs(rate @ quaternion) < 1e-14  # tangent to the unit sphere
        h = 1e-6
        R_plus = rotation_matrix(quaternion + h * rate)
        R_minus = rotation_matrix(quaternion - h * rate)
        R_dot = (R_plus - R_minus) / (2 * h)
        np.testing.assert_allclose(R_dot, skew(omega) @ R, atol=1e-8)


@pytest.mark.parametrize('tableau', TABLEAUX, ids=lambda t: t.name)
def test_rotating_axis_converges_to_the_exact_orientation(tableau):
    # R(t) = Rz(alpha t) Rx(beta t) R0 has the spatial angular velocity
    # w(t) = alpha e_z + Rz(alpha t) beta e_x. (A constant w would be too easy: the
    # renormalisation then cancels the leading error term of ode3.)
    alpha, beta = 1.3, -2.1
    R0 = rodrigues(np.array([0.3, -0.2, 0.9]))
    exact = rodrigues(np.array([0.0, 0.0, alpha])) @ rodrigues(np.array([beta, 0.0, 0.0])) @ R0

    def f(t, x):
        omega = np.array([beta * np.cos(alpha * t), beta * np.sin(alpha * t), alpha])
        return quaternion_derivative(x, omega)

    errors = []
    for dt in (0.02, 0.01, 0.005):
        x = from_rotation_matrix(R0)
        for k in range(round(1.0 / dt)):
            x = normalized(tableau.step(f, k * dt, x, dt))
            assert abs(np.linalg.norm(x) - 1.0) < 1e-15
        errors.append(np.linalg.norm(rotation_matrix(x) - exact))
    expected_ratio = 2.0**tableau.order
    for coarse, fine in itertools.pairwise(errors):
        assert 0.8 * expected_ratio < coarse / fine < 1.25 * expected_ratio, errors


def test_normalized_rejects_zero():
    with pytest.raises(ValueError, match='non-zero'):
        normalized(np.zeros(4))
