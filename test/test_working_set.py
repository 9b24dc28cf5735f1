"""The compiled working-set optimum and its KKT check against an independent solver (daqp)."""

import daqp
import numba
import numpy as np
import pytest

from grasp_safety_filter.control.working_set import (
    clipped_optimum_on_working_set,
    optimum_on_working_set,
    working_set_scratch,
)

TOLERANCE = 1e-10


def problem(rng, m=9, k=40):
    C = rng.normal(size=(k, m)) * rng.uniform(0.1, 100.0, size=(k, 1))
    b = C @ rng.normal(size=m) - rng.uniform(0.0, 2.0, size=k) * np.linalg.norm(C, axis=1)
    return rng.normal(scale=5.0, size=m), C, b


def on_working_set(y0, C, b, rows, scratch=None):
    """Return optimum_on_working_set at TOLERANCE, on new scratch unless given."""
    scratch = working_set_scratch(y0.size, b.size) if scratch is None else scratch
    return optimum_on_working_set(y0, C, b, rows, TOLERANCE, scratch)


@numba.njit
def kkt_solve(kkt, rhs):
    """Return numba's np.linalg.solve (dgesv on copies of its arguments)."""
    return np.linalg.solve(kkt, rhs)


def reference(y0, C, b):
    """Return daqp's optimum of min 1/2 ||y - y0||^2 s.t. C y >= b: (y, active, multipliers)."""
    m = y0.size
    x, _, flag, info = daqp.solve(np.eye(m), -y0, C, np.full(b.size, 1e30), b)
    assert flag == 1
    lam = info['lam']
    active = np.flatnonzero(lam < 0.0)
    return x, active, -lam[active]


@pytest.mark.parametrize('seed', range(4))
def test_the_optimal_active_set_is_accepted_with_the_reference_optimum(seed):
    rng = np.random.default_rng(seed)
    for _ in range(40):
        y0, C, b = problem(rng)
        x, active, multipliers = reference(y0, C, b)
        if not active.size:
            continue
        outcome, y, lam = on_working_set(y0, C, b, active.astype(np.intp))
        assert outcome == 1
        assert np.abs(y - x).max() < 1e-7
        assert np.allclose(lam, multipliers, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize('seed', range(4))
def test_a_wrong_set_is_refused(seed):
    rng = np.random.default_rng(100 + seed)
    refused = 0
    for _ in range(40):
        y0, C, b = problem(rng)
        _, active, _ = reference(y0, C, b)
        if not active.size:
            continue
        # One active row missing: the optimum on the rest violates it (unless degenerate).
        outcome, y, _ = on_working_set(y0, C, b, active[1:].astype(np.intp))
        violated = (C[active[0]] @ y - b[active[0]]) / np.linalg.norm(C[active[0]])
        assert (outcome == 1) == (violated >= -TOLERANCE)
        refused += outcome == 0
        # An inactive row added as an equality: a negative multiplier or a violated row.
        inactive = np.setdiff1d(np.arange(b.size), active)[:1]
        rows = np.concatenate((active, inactive)).astype(np.intp)
        if rows.size <= C.shape[1]:
            assert on_working_set(y0, C, b, rows)[0] == 0
    assert refused > 0


@pytest.mark.parametrize('seed', range(3))
def test_the_solve_is_dgesv_on_the_dense_kkt_system_to_the_bit(seed):
    """One scratch reused on working sets of every size gives np.linalg.solve's answers."""
    rng = np.random.default_rng(200 + seed)
    y0, C, b = problem(rng)
    m, k = C.shape[1], C.shape[0]
    scratch = working_set_scratch(m, k)
    for q in rng.integers(1, m + 1, size=30):
        rows = rng.choice(k, q, replace=False).astype(np.intp)
        kkt = np.zeros((m + q, m + q))
        kkt[:m, :m] = np.eye(m)
        kkt[:m, m:], kkt[m:, :m] = -C[rows].T, C[rows]
        rhs = np.zeros(m + q)
        for a, r in enumerate(rows):
            rhs[m + a] = b[r]
            for c in range(m):  # the kernel's order of the sum
                rhs[m + a] -= C[r, c] * y0[c]
        solution = kkt_solve(kkt, rhs)
        _, y, lam = on_working_set(y0, C, b, rows, scratch)
        np.testing.assert_array_equal(y, y0 + solution[:m])
        np.testing.assert_array_equal(lam, solution[m:])


def test_a_scratch_made_for_fewer_rows_is_refused_before_it_is_written():
    rng = np.random.default_rng(7)
    y0, C, b = problem(rng)
    m, k = C.shape[1], C.shape[0]
    with pytest.raises(ValueError, match='scratch too small'):
        on_working_set(y0, C, b, np.array([0]), working_set_scratch(m, k - 1))


def test_dependent_rows_are_singular():
    C = np.array([[1.0, 0.0], [2.0, 0.0], [0.0, 1.0]])
    b = np.array([1.0, 2.0, 0.0])
    assert on_working_set(np.zeros(2), C, b, np.array([0, 1]))[0] == -1


def test_a_null_row_holds_only_if_its_residual_does():
    C = np.array([[1.0, 0.0], [0.0, 0.0]])
    y0 = np.zeros(2)
    rows = np.array([0])
    assert on_working_set(y0, C, np.array([1.0, -1.0]), rows)[0] == 1
    assert on_working_set(y0, C, np.array([1.0, 1.0]), rows)[0] == 0


@pytest.mark.parametrize('seed', range(3))
def test_the_clipped_optimum_agrees_with_the_solve_clip_and_row_check(seed):
    """clipped_optimum_on_working_set against its three steps done separately in numpy."""
    rng = np.random.default_rng(100 + seed)
    accepted = rejected = 0
    for _ in range(60):
        y0, C, b = problem(rng)
        _, active, _ = reference(y0, C, b)
        if not active.size:
            continue
        guess = active if rng.uniform() < 0.7 else active[:-1]
        bound = rng.uniform(0.5, 20.0)
        u_min, u_max = np.full(y0.size, -bound), np.full(y0.size, bound)
        A, lower = C[:30], b[:30] - rng.uniform(0.0, 1e-5, 30)
        outcome, u, lam = clipped_optimum_on_working_set(
            y0, C, b, guess.astype(np.intp), TOLERANCE, u_min, u_max, A, lower, 1e-6,
            working_set_scratch(y0.size, b.size),
        )
        expected_outcome, y, expected_lam = on_working_set(y0, C, b, guess.astype(np.intp))
        if expected_outcome != 1:
            assert outcome == expected_outcome
            continue
        clipped = np.minimum(np.maximum(y, u_min), u_max)
        violation = max(0.0, float(np.max(lower - A @ clipped)))
        assert outcome == (1 if violation <= 1e-6 else 0)
        np.testing.assert_array_equal(u, clipped)
        np.testing.assert_array_equal(lam, expected_lam)
        accepted += outcome == 1
        rejected += outcome == 0
    assert accepted and rejected  # both answers were exercised
