"""The exact least-distance QP (dual active-set method) against an independent solver."""

import daqp
import numpy as np
import pytest
from scipy.optimize import linprog

from grasp_safety_filter.control.least_distance import (
    LeastDistanceStatus,
    solve_least_distance,
)
from grasp_safety_filter.control.qp_metric import (
    metric_matrix,
    metric_row_norms,
    to_metric_coordinates,
    write_inertia_factor,
)


def reference(u0, C, b):
    """Solve min 1/2 ||u - u0||^2 s.t. C u >= b with daqp: (exitflag, u)."""
    m = u0.size
    x, _, flag, _ = daqp.solve(np.eye(m), -u0, C, np.full(b.size, 1e30), b)
    return flag, x


def feasible_by_lp(C, b):
    result = linprog(np.zeros(C.shape[1]), A_ub=-C, b_ub=-b, bounds=(None, None), method='highs')
    return result.status == 0


def random_problem(rng, m=9, k=40, dependent=0):
    C = rng.normal(size=(k, m)) * rng.uniform(0.1, 100.0, size=(k, 1))
    if dependent:
        # Rows inside a low-dimensional span: the filter's barrier rows live in the
        # 6-dimensional image of the object's motion.
        basis = rng.normal(size=(dependent, m))
        C[: k // 2] = rng.normal(size=(k // 2, dependent)) @ basis
    centre = rng.normal(size=m)
    b = C @ centre - rng.uniform(0.0, 2.0, size=k) * np.linalg.norm(C, axis=1)
    return rng.normal(scale=5.0, size=m), C, b


@pytest.mark.parametrize('dependent', [0, 3, 6])
def test_optimum_matches_an_independent_solver(dependent):
    rng = np.random.default_rng(dependent)
    for _ in range(60):
        u0, C, b = random_problem(rng, dependent=dependent)
        solution = solve_least_distance(u0, C, b)
        flag, x = reference(u0, C, b)
        assert flag == 1
        assert solution.status is LeastDistanceStatus.OPTIMAL
        assert np.abs(solution.u - x).max() < 1e-7
        assert (C @ solution.u - b).min() >= -1e-7 * np.linalg.norm(C, axis=1).max()
        # KKT: u - u0 = C_W^T lambda with lambda >= 0 and the working rows held.
        rows = list(solution.active)
        assert np.all(solution.multipliers >= 0.0)
        assert np.allclose(u0 + C[rows].T @ solution.multipliers, solution.u, atol=1e-8)
        assert np.allclose(C[rows] @ solution.u, b[rows], rtol=1e-9, atol=1e-7)


def test_infeasibility_agrees_with_a_linear_program():
    rng = np.random.default_rng(3)
    verdicts = {True: 0, False: 0}
    for _ in range(80):
        m, k = 4, 12
        C = rng.normal(size=(k, m))
        b = rng.normal(scale=1.5, size=k) + 0.8
        solution = solve_least_distance(np.zeros(m), C, b)
        feasible = feasible_by_lp(C, b)
        verdicts[feasible] += 1
        assert (solution.status is LeastDistanceStatus.OPTIMAL) == feasible
    assert verdicts[True] > 5 and verdicts[False] > 5


def test_a_correct_guess_is_certified_without_a_step_and_a_wrong_one_is_repaired():
    rng = np.random.default_rng(4)
    for _ in range(30):
        u0, C, b = random_problem(rng)
        cold = solve_least_distance(u0, C, b)
        warm = solve_least_distance(u0, C, b, working_set=cold.active)
        assert warm.iterations == 0
        assert np.allclose(warm.u, cold.u, atol=1e-9)
        wrong = tuple(rng.choice(C.shape[0], size=5, replace=False))
        repaired = solve_least_distance(u0, C, b, working_set=wrong)
        assert repaired.status is LeastDistanceStatus.OPTIMAL
        assert np.allclose(repaired.u, cold.u, atol=1e-7)


def test_degenerate_rows_and_zero_rows():
    # The same row three times and its negative shifted: a slab of width 1, with u0 outside.
    C = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]])
    b = np.array([1.0, 1.0, 1.0, -2.0, -1.0])
    solution = solve_least_distance(np.array([5.0, 3.0]), C, b)
    assert solution.status is LeastDistanceStatus.OPTIMAL
    assert np.allclose(solution.u, [2.0, 3.0])
    # A zero row with a positive bound can never hold.
    b[4] = 1.0
    assert solve_least_distance(np.zeros(2), C, b).status is LeastDistanceStatus.INFEASIBLE


def test_no_rows_returns_the_start():
    solution = solve_least_distance(np.array([1.0, 2.0]), np.zeros((0, 2)), np.zeros(0))
    assert solution.status is LeastDistanceStatus.OPTIMAL
    assert np.array_equal(solution.u, [1.0, 2.0])


@pytest.mark.parametrize('seed', range(6))
def test_a_general_metric_by_the_change_of_variables_is_the_optimum_of_daqp_with_h(seed):
    """``min 1/2 du^T W du`` by ``u = R y`` (qp_metric's factor) equals daqp with ``H = W``.

    M is an ill-conditioned SPD matrix (condition ~1e4, as a hand's joint inertia): R R^T =
    M / (tr M / m), W = (tr M / m) M^-1; the multipliers of the y problem are those of u.
    """
    rng = np.random.default_rng(100 + seed)
    m = 16
    Q, _ = np.linalg.qr(rng.normal(size=(m, m)))
    M = Q @ np.diag(10.0 ** rng.uniform(-6.0, -2.0, m)) @ Q.T
    R = np.zeros((m, m))
    write_inertia_factor(M, R)
    c = np.trace(M) / m
    np.testing.assert_allclose(R @ R.T, M / c, rtol=1e-10, atol=1e-12)
    assert np.allclose(R, np.tril(R))
    W = c * np.linalg.inv(M)
    np.testing.assert_allclose(metric_matrix(R), W, rtol=1e-8, atol=1e-8 * np.abs(W).max())
    u0, C, b = random_problem(rng, m=m, k=30)
    np.testing.assert_allclose(
        metric_row_norms(C, R), np.sqrt(np.einsum('ij,jk,ik->i', C, M / c, C)), rtol=1e-10
    )
    x, _, flag, _ = daqp.solve(W, -W @ u0, C, np.full(b.size, 1e30), b)
    y = solve_least_distance(to_metric_coordinates(R, u0), C @ R, b)
    assert (flag == 1) == (y.status is LeastDistanceStatus.OPTIMAL)
    if flag == 1:
        u = R @ y.u
        np.testing.assert_allclose(u, x, atol=1e-7 * (1.0 + np.abs(u0).max()))
        # The same multipliers: W (u - u0) = C_W^T lambda.
        stationarity = W @ (u - u0) - C[list(y.active)].T @ y.multipliers
        assert np.abs(stationarity).max() <= 1e-7 * (1.0 + np.abs(W @ (u - u0)).max())


def test_the_metric_factor_refuses_an_inertia_that_is_not_positive_definite():
    R = np.zeros((3, 3))
    with pytest.raises(ValueError, match='M_h: expected a positive definite'):
        write_inertia_factor(np.diag([1.0, -1.0, 1.0]), R)
    with pytest.raises(ValueError, match='M_h: expected a finite'):
        write_inertia_factor(np.diag([1.0, np.nan, 1.0]), R)


def _identity_problems(rng):
    """Random problems like the filter's: hard and relaxed, feasible and not, nearly dependent."""
    for _ in range(400):
        m = int(rng.choice([2, 3, 9, 16, 28]))
        k = int(rng.integers(0, 3 * m + 8))
        C = rng.normal(size=(k, m)) * 10.0 ** rng.uniform(-2.0, 2.0, size=(k, 1))
        if k >= 4 and rng.random() < 0.5:
            # Rows in a low-dimensional span, some nearly repeated, and a null row.
            rank = int(rng.integers(1, m + 1))
            C[: k // 2] = rng.normal(size=(k // 2, rank)) @ rng.normal(size=(rank, m))
            C[1] = C[0] * (1.0 + 1e-10 * rng.normal()) + 1e-12 * rng.normal(size=m)
            C[2] = 0.0
        centre = rng.normal(size=m)
        b = C @ centre - rng.uniform(-0.5, 2.0, size=k) * np.linalg.norm(C, axis=1)
        if k:
            b[rng.random(k) < 0.05] = 0.0
            b[np.linalg.norm(C, axis=1) == 0.0] = -1.0 if rng.random() < 0.9 else 1.0
        u0 = rng.normal(scale=5.0, size=m)
        guesses = [(), tuple(rng.integers(0, max(k, 1), size=min(k, 5)))] if k else [()]
        yield u0, C, b, guesses


def test_the_compiled_solver_is_the_numpy_formulation():
    """Every field of every solution equals the numpy formulation's (least_distance_oracle).

    The kernel calls scipy's BLAS and LAPACK, the oracle numpy's; where both libraries run the
    same kernels (the machines this is measured on) the solutions are equal to the bit. The
    comparison allows 1e-12 of the problem's scale in u and the multipliers so that a BLAS
    build whose kernels round differently does not fail it; statuses, active sets and
    iteration counts must be equal.
    """
    import least_distance_oracle

    rng = np.random.default_rng(11)
    statuses = set()
    for u0, C, b, guesses in _identity_problems(rng):
        cold = least_distance_oracle.solve_least_distance(u0, C, b)
        guesses.append(cold.active)
        for guess in guesses:
            for max_iter in (None, 2):
                expected = least_distance_oracle.solve_least_distance(
                    u0, C, b, max_iter=max_iter, working_set=guess
                )
                found = solve_least_distance(u0, C, b, max_iter=max_iter, working_set=guess)
                statuses.add(expected.status)
                assert found.status is expected.status
                assert found.active == expected.active
                assert found.iterations == expected.iterations
                scale = 1.0 + np.abs(expected.u).max(initial=0.0)
                np.testing.assert_allclose(found.u, expected.u, rtol=0.0, atol=1e-12 * scale)
                np.testing.assert_allclose(
                    found.multipliers,
                    expected.multipliers,
                    rtol=1e-12,
                    atol=1e-12 * (1.0 + np.abs(expected.multipliers).max(initial=0.0)),
                )
    assert statuses == set(LeastDistanceStatus)
