"""The safety filter's QP as every backend sees it: a :class:`Problem` and its :class:`Solution`.

In the style of qpsolvers (S. Caron): the problem is data, a backend maps it to a
:class:`Solution`, and the solution measures its own residuals against the problem.

The hard problem, over the m joint torques u, with the metric H (the identity, the
paper's; or ``W = (R R^T)^-1`` of :mod:`~grasp_safety_filter.control.qp`, R the
problem's ``metric_factor``) and ``u_nom = -g``::

    min_u    1/2 (u - u_nom)^T H (u - u_nom)
    s.t.     A u >= lower,   u_min <= u <= u_max

The relaxed problem (``slack_weights`` w given) adds one slack s_r >= 0 per barrier row r,
normalised to a distance in the metric by the row's dual norm ``d_r = ||R^T A_r||``
(``||A_r||`` for the identity, N·m; 1 below ``ROW_NORM_FLOOR``)::

    min_u,s  1/2 (u - u_nom)^T H (u - u_nom) + 1/2 sum_r w_r s_r^2
    s.t.     A u + d_r s_r >= lower_r,   u_min <= u <= u_max,   s >= 0

Every backend answers with a :class:`Solution` whose rows the solution itself measures
(:meth:`Solution.row_violation`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from grasp_safety_filter.control.qp import metric_matrix, metric_row_norms, ROW_NORM_FLOOR

#: A row ``A u >= lower`` counts as satisfied when ``A u - lower >= -FEASIBILITY_TOLERANCE``
#: (in the row's unit: N for no slip, rad/s² for the barriers).
FEASIBILITY_TOLERANCE = 1e-6


class SolutionStatus(str, Enum):
    """What a backend established about its problem."""

    OPTIMAL = 'optimal'
    """``u`` is the optimum: the KKT conditions hold to the backend's tolerance."""
    INFEASIBLE = 'infeasible'
    """No torque satisfies every row and the box (proved, not a time-out)."""
    FAILED = 'failed'
    """No usable answer: iteration limit, numerical trouble or a non-finite result."""


@dataclass(frozen=True, eq=False)
class Problem:
    """One tick's QP (see the module docstring for the math).

    The arrays may be views of buffers the caller rewrites every tick: a backend reads
    them at each ``solve`` and keeps nothing derived from their values.

    Attributes:
        g: The nominal torque, negated, shape (m,): ``-u_nom`` (the linear cost for the
            identity metric; ``H g`` is it otherwise).
        A: Barrier rows, shape (k, m).
        lower: Their lower bounds, shape (k,).
        u_min, u_max: The actuator box, shape (m,) each.
        slack_weights: w, shape (k,), all > 0, for the relaxed problem; None when hard.
        metric_factor: R of the metric ``H = (R R^T)^-1``, shape (m, m), lower triangular
            with a positive diagonal; None for the identity (the paper's).
    """

    g: np.ndarray
    A: np.ndarray
    lower: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    slack_weights: np.ndarray | None = None
    metric_factor: np.ndarray | None = None

    def __post_init__(self) -> None:
        m = self.g.shape[0]
        k = self.lower.shape[0]
        if self.A.shape != (k, m) or self.u_min.shape != (m,) or self.u_max.shape != (m,):
            raise ValueError(
                f'Problem: expected A ({k}, {m}) and a box of ({m},), got A {self.A.shape}, '
                f'u_min {self.u_min.shape}, u_max {self.u_max.shape}'
            )
        weights = self.slack_weights
        if weights is not None and (
            weights.shape != (k,) or not np.all(np.isfinite(weights) & (weights > 0.0))
        ):
            raise ValueError(f'Problem: expected {k} finite slack weights > 0, got {weights!r}')
        R = self.metric_factor
        if R is not None and R.shape != (m, m):
            raise ValueError(
                f'Problem: expected a metric factor of shape ({m}, {m}), got {R.shape}'
            )

    @property
    def n_torques(self) -> int:
        """m, the number of torques."""
        return self.g.shape[0]

    @property
    def n_rows(self) -> int:
        """k, the number of barrier rows."""
        return self.lower.shape[0]

    @property
    def H(self) -> np.ndarray:
        """The cost matrix: the identity, or ``(R R^T)^-1`` with a metric factor R."""
        if self.metric_factor is None:
            return np.eye(self.n_torques)
        return metric_matrix(self.metric_factor)

    @property
    def relaxed(self) -> bool:
        """True for the relaxed problem (slack variables present)."""
        return self.slack_weights is not None

    def with_slack(self, weights: np.ndarray) -> Problem:
        """Return the relaxed problem on the same arrays, with slack weights w."""
        return Problem(
            self.g, self.A, self.lower, self.u_min, self.u_max, weights, self.metric_factor
        )

    def slack_scale(self) -> np.ndarray:
        """Return ``d_r = ||R^T A_r||`` (``||A_r||``; 1 below :data:`ROW_NORM_FLOOR`), (k,)."""
        norms = metric_row_norms(self.A, self.metric_factor)
        return np.where(norms < ROW_NORM_FLOOR, 1.0, norms)


@dataclass(frozen=True, eq=False)
class Solution:
    """A backend's answer to a :class:`Problem`.

    Attributes:
        u: The torque, shape (m,), inside the box whenever finite.
        status: :class:`SolutionStatus`.
        slack: The relaxed problem's slack s (N·m, or W's distance), shape (k,); None when
            hard.
        iterations: The QP solvers' own iterations (0: none was called).
    """

    u: np.ndarray
    status: SolutionStatus
    slack: np.ndarray | None = None
    iterations: int = 0

    @property
    def optimal(self) -> bool:
        """True when the backend found the optimum."""
        return self.status is SolutionStatus.OPTIMAL

    def row_violation(self, problem: Problem) -> float:
        """``max(0, max_r (lower_r - A_r u - d_r s_r))`` in the rows' own units (N, rad/s²)."""
        if not problem.n_rows:
            return 0.0
        residual = problem.A @ self.u
        with np.errstate(invalid='ignore'):
            residual -= problem.lower
            if problem.relaxed and self.slack is not None:
                residual += problem.slack_scale() * self.slack
        worst = -float(residual.min())  # NaN when a residual is
        return max(worst, 0.0) if worst == worst else float('inf')
