"""The metric's compiled steps against the numpy and scipy calls they stand for, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from grasp_safety_filter.control.metric_kernel import (
    inertia_factor,
    metric_optimum_on_working_set,
    numpy_sum,
)
from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.control.qp_metric import to_metric_coordinates, write_inertia_factor
from grasp_safety_filter.control.working_set import optimum_on_working_set, working_set_scratch
from grasp_safety_filter.model.fortran_linalg import matrix_matrix, matrix_vector

SIZES = (2, 3, 7, 8, 9, 12, 16, 17, 40)


def _inertia(rng, m):
    """Return a positive definite (m, m) matrix of entries over several decades."""
    X = rng.normal(size=(m, m)) * 10.0 ** rng.uniform(-3, 2, (m, m))
    return X @ X.T + np.diag(rng.uniform(0.0, 1.0, m)) * 10.0 ** rng.uniform(-4, 1)


@pytest.mark.parametrize('m', SIZES)
def test_the_trace_the_factor_and_the_products_are_numpys(m):
    rng = np.random.default_rng(m)
    for _ in range(40):
        M = _inertia(rng, m)
        terms = np.concatenate((rng.normal(size=3), M.ravel()))
        assert numpy_sum(terms, 3, m + 1, m) == np.trace(M)
        R, factor, expected = np.full((m, m), np.nan), np.empty(m * m), np.empty((m, m))
        assert inertia_factor(terms, 3, R, factor)
        write_inertia_factor(M, expected)
        np.testing.assert_array_equal(R, expected)
        np.testing.assert_array_equal(factor.reshape(m, m).T, expected)
        k = int(rng.integers(1, 40))
        C = rng.normal(size=(k + 2 * m, m)) * 10.0 ** rng.uniform(-3, 3, (k + 2 * m, m))
        out = np.empty_like(C)
        matrix_matrix(C, R, out)
        np.testing.assert_array_equal(out, C @ expected)
        y = rng.normal(size=m)
        u = np.empty(m)
        matrix_vector(m, m, R.reshape(-1), 0, m, 1, y, u)
        np.testing.assert_array_equal(u, expected @ y)


def test_a_matrix_that_is_not_positive_definite_or_finite_gives_no_factor():
    M = np.diag([1.0, -1.0, 2.0])
    R, factor = np.full((3, 3), 7.0), np.empty(9)
    assert not inertia_factor(M.ravel(), 0, R, factor)
    M[0, 0] = np.inf
    assert not inertia_factor(M.ravel(), 0, R, factor)
    assert (R == 7.0).all()  # untouched, as write_inertia_factor leaves its output


@pytest.mark.parametrize('m', (3, 9, 16))
def test_the_guess_in_metric_coordinates_is_the_backends(m):
    """Rows C R, y_nom, the optimum on W, u = R y clipped and the row check, as numpy's."""
    rng = np.random.default_rng(100 + m)
    k = 2 * m
    qp = SafetyQP(m, k, -np.ones(m), np.ones(m), metric=True)
    settled = rejected = 0
    for _ in range(60):
        M = _inertia(rng, m)
        R, factor = np.empty((m, m)), np.empty(m * m)
        assert inertia_factor(M.ravel(), 0, R, factor)
        qp.A_rows[:] = rng.normal(size=(k, m))
        u_nom = rng.normal(0.0, 0.1, m)
        # Every row loose at u_nom but one, which it violates a little: often the optimum's
        # only active row; half the time a random working set instead (rarely optimal).
        qp.lower_rows[:] = qp.A_rows @ u_nom - rng.uniform(0.5, 1.0, k)
        qp.lower_rows[0] += 1.05
        working_set = np.array([0]) if rng.random() < 0.5 else rng.choice(k, 2, replace=False)
        C = np.concatenate((qp.A_rows, np.zeros((2 * m, m))))
        C[k::2], C[k + 1 :: 2] = np.eye(m), -np.eye(m)
        b = np.concatenate((qp.lower_rows, -np.ones(2 * m)))
        rows_y, y_nom = np.empty_like(C), np.empty(m)
        outcome, u, multipliers = metric_optimum_on_working_set(
            C, b, working_set, (R, factor, rows_y, y_nom), u_nom, (-np.ones(m), np.ones(m)),
            (qp.C_data, qp.lower_rows), (1e-10, 1e-6), working_set_scratch(m, C.shape[0]),
        )
        np.testing.assert_array_equal(rows_y, C @ R)
        np.testing.assert_array_equal(y_nom, to_metric_coordinates(R, u_nom))
        expected, y, lam = optimum_on_working_set(
            y_nom, C @ R, b, working_set, 1e-10, working_set_scratch(m, C.shape[0])
        )
        if expected != 1:
            assert outcome == expected
            rejected += 1
            continue
        u_expected = np.minimum(np.maximum(R @ y, -1.0), 1.0)
        holds = (qp.A_rows @ u_expected - qp.lower_rows).min() >= -1e-6
        assert outcome == (1 if holds else 0)
        np.testing.assert_array_equal(u, u_expected)
        np.testing.assert_array_equal(multipliers, lam)
        settled += holds
    assert settled and rejected
