"""The compiled row checks against the numpy expressions they stand for."""

from __future__ import annotations

import numpy as np
import pytest

from grasp_safety_filter.control.filter_result import box_margins, residuals, violations
from grasp_safety_filter.control.filter_rows import all_finite, inside


def _rows(rng, k=20, m=9):
    A = rng.normal(size=(k, m))
    u = rng.normal(size=m)
    lower = A @ u - rng.uniform(-0.5, 2.0, k)
    return A, lower, u


@pytest.mark.parametrize('seed', range(4))
def test_residuals_and_their_minimum_match_numpy(seed):
    rng = np.random.default_rng(seed)
    A, lower, u = _rows(rng)
    out = np.full(A.shape[0] + 3, 7.0)
    smallest = residuals(A, lower, u, out)
    np.testing.assert_allclose(out[:-3], A @ u - lower, rtol=0, atol=1e-12)
    assert (out[-3:] == 7.0).all()
    assert smallest == out[:-3].min()
    lower[5] = np.nan
    assert np.isnan(residuals(A, lower, u, out))
    assert residuals(A[:0], lower[:0], u, out) == np.inf


@pytest.mark.parametrize('seed', range(4))
def test_inside_matches_the_rows_and_the_box(seed):
    rng = np.random.default_rng(10 + seed)
    for _ in range(50):
        A, lower, u = _rows(rng)
        u_min, u_max = -np.abs(rng.normal(2.0, 1.0, u.size)), np.abs(rng.normal(2.0, 1.0, u.size))
        expected = bool((A @ u >= lower).all() and (u >= u_min).all() and (u <= u_max).all())
        assert inside(A, lower, u, u_min, u_max) is expected
    u[0] = np.nan
    assert not inside(A, lower - 100.0, u, u_min - 100.0, u_max + 100.0)


def test_all_finite_finds_inf_and_nan_in_either_array():
    a, b = np.ones(5), np.zeros(3)
    assert all_finite(a, b)
    for bad in (np.inf, -np.inf, np.nan):
        for array in (a, b):
            array[1] = bad
            assert not all_finite(a, b)
            array[1] = 0.5


@pytest.mark.parametrize('seed', range(4))
def test_box_margins_are_the_numpy_subtractions_bit_for_bit(seed):
    rng = np.random.default_rng(20 + seed)
    u = rng.normal(size=9)
    u_min, u_max = -np.abs(rng.normal(2.0, 1.0, 9)), np.abs(rng.normal(2.0, 1.0, 9))
    out = np.full(2 * u.size + 1, 7.0)
    box_margins(u, u_min, u_max, out[1:])
    assert out[0] == 7.0
    assert np.array_equal(out[1::2], u - u_min)
    assert np.array_equal(out[2::2], u_max - u)


@pytest.mark.parametrize('seed', range(4))
def test_violations_flag_the_groups_numpy_finds_and_the_worst_row(seed):
    rng = np.random.default_rng(30 + seed)
    tolerance = 1e-6
    group = np.repeat(np.arange(4, dtype=np.intp), [6, 5, 1, 8])
    for _ in range(50):
        residual = rng.normal(size=group.size) * rng.choice([1e-7, 1.0], size=group.size)
        flags = np.zeros(4, dtype=np.bool_)
        worst = violations(residual, group, tolerance, flags)
        expected = np.zeros(4, dtype=bool)
        expected[np.unique(group[~(residual >= -tolerance)])] = True
        assert np.array_equal(flags, expected)
        assert worst == np.max(-residual)
    residual[3] = np.nan
    flags = np.zeros(4, dtype=np.bool_)
    assert np.isnan(violations(residual, group, tolerance, flags))
    assert flags[0]
