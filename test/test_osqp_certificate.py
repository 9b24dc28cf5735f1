"""OSQP's dual vector read as the problem's active rows, against a plain-Python reading."""

from __future__ import annotations

import numpy as np
import pytest

from grasp_safety_filter.control.qp_solvers.osqp_certificate import working_set_guess


def _guess_oracle(y: np.ndarray, k: int, m: int) -> tuple[int, ...]:
    """Read y entry by entry, largest |y| first (the reading the compiled loop replaces)."""
    magnitude = np.abs(y)
    threshold = 1e-9 * max(1.0, float(magnitude.max(initial=0.0)))
    rows = []
    for i in np.argsort(-magnitude):
        if magnitude[i] <= threshold:
            break
        if k <= i < k + m:
            rows.append(int(k + 2 * (i - k) + (1 if y[i] > 0.0 else 0)))
        elif y[i] < 0.0:
            rows.append(int(i) if i < k else int(i + m))
    return tuple(rows)


@pytest.mark.parametrize('relaxed', [False, True])
@pytest.mark.parametrize('seed', range(3))
def test_working_set_guess_matches_the_oracle(seed, relaxed):
    rng = np.random.default_rng(seed)
    k, m = 20, 9
    size = 2 * k + m if relaxed else k + m
    for trial in range(200):
        y = np.zeros(size)
        chosen = rng.choice(size, rng.integers(0, size), replace=False)
        y[chosen] = rng.normal(size=chosen.size) * 10.0 ** rng.uniform(-12, 3)
        if trial % 5 == 0:
            y[chosen[: chosen.size // 2]] = -1.5  # ties
        if trial % 7 == 0:
            y[rng.integers(size)] = np.nan
        guess = working_set_guess(y, k, m)
        assert guess == _guess_oracle(y, k, m)
        assert all(type(row) is int for row in guess)


def test_working_set_guess_names_box_sides_and_skips_upper_bounded_rows():
    k, m = 2, 2
    y = np.array([-3.0, 2.0, 1.0, -4.0])  # row 0 lower, row 1 > 0 (no row), box 0 up, 1 low
    assert working_set_guess(y, k, m) == (k + 2, 0, k + 1)
