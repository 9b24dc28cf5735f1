"""The safety filter's QP as every backend sees it: a :class:`Problem` and its :class:`Solution`.

In the style of qpsolvers (S. Caron): the problem is data, a backend maps it to a
:class:`Solution`, and the solution measures its own residuals against the problem.

The hard problem, over the m joint torques u, with the metric H (the identity, the
paper's; or ``W = (R R^T)^-1`` of :mod:`~grasp_safety_filter.control.qp_metric`, R the
problem's ``metric_factor``) and ``u_nom = -g``::

    min_u    1/2 (u - u_nom)^T H (u - u_nom)
    s.t.     A u >= lower,   u_min <= u <= u_max

The relaxed problem (``slack_weights`` w given) adds one slack s_r >= 0 per barrier row r,
normalised to a distance in the metric by the row's dual norm ``d_r = ||R^T A_r||``
(``||A_r||`` for the identity, N·m; 1 below ``ROW_NORM_FLOOR``)::

    min_u,s  1/2 (u - u_nom)^T H (u - u_nom) + 1/2 sum_r w_r s_r^2
    s.t.     A u + d_r s_r >= lower_r,   u_min <= u <= u_max,   s >= 0

Both are least-distance problems ``min 1/2 ||x - x0||^2 s.t. C x >= b``
(:meth:`Problem.least_distance_form`), with ``y = R^-1 u`` (``y = u`` for the identity):
hard, ``x = y``, ``x0 = R^-1 u_nom``; relaxed, ``x = (y, s~)`` with ``s~ = sqrt(w) s`` and
``x0 = (R^-1 u_nom, 0)``. Its rows, in the one row numbering of every :class:`Solution`'s
active set (``C`` holds them times R in the y columns):

- ``0 .. k-1``: the barrier rows ``A_r u (+ d_r / sqrt(w_r) s~_r) >= lower_r``,
- ``k + 2 j``: ``u_j >= u_min,j``;  ``k + 2 j + 1``: ``-u_j >= -u_max,j``,
- ``k + 2 m + r`` (relaxed only): ``s~_r >= 0``.

Multipliers are those of this form (``lambda >= 0``, ``x - x0 = C_W^T lambda_W``), which
are also the multipliers in u: ``H (u - u_nom) = [A; B]_W^T lambda_W``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import NamedTuple

import numpy as np

# The relaxed problem's slack normalisation, one definition for every form of it.
from grasp_safety_filter.control.constraints.base import box_rows
from grasp_safety_filter.control.qp import ROW_NORM_FLOOR
from grasp_safety_filter.control.qp_metric import (
    metric_matrix,
    metric_row_norms,
    to_metric_coordinates,
)

#: A row ``A u >= lower`` counts as satisfied when ``A u - lower >= -FEASIBILITY_TOLERANCE``
#: (in the row's unit: N for no slip, rad/s² for the barriers).
FEASIBILITY_TOLERANCE = 1e-6


class SolutionStatus(str, Enum):
    """What a backend established about its problem."""

    OPTIMAL = 'optimal'
    """``u`` is the optimum: the KKT conditions hold to the backend's tolerance."""
    INFEASIBLE = 'infeasible'
    """No torque satisfies every row and the box (proved, not a time-out)."""
    INACCURATE = 'inaccurate'
    """A finite ``u`` the backend could not prove optimal (a solver's last iterate)."""
    FAILED = 'failed'
    """No usable answer: iteration limit, numerical trouble or a non-finite result."""


@dataclass(frozen=True, eq=False)
class Problem:
    """One tick's QP (see the module docstring for the math and the row numbering).

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
    _box: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False)

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
        object.__setattr__(self, '_box', box_rows(self.u_min, self.u_max))

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

    def to_metric_coordinates(self, u: np.ndarray) -> np.ndarray:
        """Return ``R^-1 u`` (u itself for the identity): the least-distance form's y."""
        if self.metric_factor is None:
            return u
        return to_metric_coordinates(self.metric_factor, u)

    @property
    def relaxed(self) -> bool:
        """True for the relaxed problem (slack variables present)."""
        return self.slack_weights is not None

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The box as rows ``(B, c)``, ``B u >= c`` (:func:`box_rows`)."""
        return self._box

    def with_slack(self, weights: np.ndarray) -> Problem:
        """Return the relaxed problem on the same arrays, with slack weights w."""
        return Problem(
            self.g, self.A, self.lower, self.u_min, self.u_max, weights, self.metric_factor
        )

    def slack_scale(self) -> np.ndarray:
        """Return ``d_r = ||R^T A_r||`` (``||A_r||``; 1 below :data:`ROW_NORM_FLOOR`), (k,)."""
        norms = metric_row_norms(self.A, self.metric_factor)
        return np.where(norms < ROW_NORM_FLOOR, 1.0, norms)

    def least_distance_form(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(x0, C, b)``: the problem as ``min 1/2 ||x - x0||^2 s.t. C x >= b``."""
        m, k = self.n_torques, self.n_rows
        B, c = self._box
        R = self.metric_factor
        rows = np.concatenate((self.A, B))
        if R is not None:
            rows = rows @ R
        y0 = self.to_metric_coordinates(-self.g)
        if not self.relaxed:
            return y0, rows, np.concatenate((self.lower, c))
        C = np.zeros((2 * k + 2 * m, m + k))
        C[: k + 2 * m, :m] = rows
        C[np.arange(k), m + np.arange(k)] = self.slack_scale() / np.sqrt(self.slack_weights)
        C[k + 2 * m :, m:] = np.eye(k)
        b = np.concatenate((self.lower, c, np.zeros(k)))
        return np.concatenate((y0, np.zeros(k))), C, b


class Residuals(NamedTuple):
    """KKT residuals of a solution, in the least-distance form's units (N·m for torques).

    Attributes:
        primal: Largest row violation, ``max(0, max_i (b_i - C_i x) / ||C_i||)``.
        dual: ``max |x - x0 - C_W^T lambda_W|`` (stationarity), inf if a multiplier < 0.
        complementarity: ``max_i lambda_i |C_i x - b_i| / ||C_i||`` over the active rows.
    """

    primal: float
    dual: float
    complementarity: float


_NO_MULTIPLIERS = np.zeros(0)
_NO_MULTIPLIERS.setflags(write=False)


@dataclass(frozen=True, eq=False)
class Solution:
    """A backend's answer to a :class:`Problem`.

    Attributes:
        u: The torque, shape (m,), inside the box whenever finite.
        status: :class:`SolutionStatus`.
        active: Active rows in the problem's row numbering (OPTIMAL), or the rows that
            prove infeasibility (INFEASIBLE, when the backend knows them).
        multipliers: Their multipliers ``lambda >= 0`` (least-distance form), same order.
        slack: The relaxed problem's slack s (N·m, or W's distance), shape (k,); None when
            hard.
        iterations: The QP solver's own iterations (0: it was not called).
        refinement_steps: Exact active-set steps after the solver (add or drop a row).
    """

    u: np.ndarray
    status: SolutionStatus
    active: tuple[int, ...] = ()
    multipliers: np.ndarray = field(default_factory=lambda: _NO_MULTIPLIERS)
    slack: np.ndarray | None = None
    iterations: int = 0
    refinement_steps: int = 0

    @property
    def optimal(self) -> bool:
        """True when the backend found the optimum."""
        return self.status is SolutionStatus.OPTIMAL

    def x(self, problem: Problem) -> np.ndarray:
        """Return the least-distance form's variable: y, or ``(y, sqrt(w) s)`` when relaxed.

        ``y = R^-1 u`` (u for the identity metric).
        """
        y = problem.to_metric_coordinates(self.u)
        if not problem.relaxed:
            return y
        slack = self.slack if self.slack is not None else np.zeros(problem.n_rows)
        return np.concatenate((y, np.sqrt(problem.slack_weights) * slack))

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

    def residuals(self, problem: Problem) -> Residuals:
        """Return the KKT residuals of ``(u, s, active, multipliers)`` on ``problem``."""
        x0, C, b = problem.least_distance_form()
        x = self.x(problem)
        if not np.isfinite(x).all():
            return Residuals(np.inf, np.inf, np.inf)
        norms = np.maximum(np.sqrt(np.einsum('ij,ij->i', C, C)), 1e-12)
        distance = (C @ x - b) / norms
        rows = list(self.active)
        lam = np.asarray(self.multipliers, dtype=float)
        gradient = x - x0 - C[rows].T @ lam if rows else x - x0
        dual = float(np.abs(gradient).max(initial=0.0))
        if lam.size and lam.min() < 0.0:
            dual = np.inf
        complementarity = float(
            np.max(lam * np.abs(distance[rows]) * norms[rows], initial=0.0) if rows else 0.0
        )
        return Residuals(float(max(0.0, -distance.min(initial=0.0))), dual, complementarity)

    def is_optimal(self, problem: Problem, tolerance: float) -> bool:
        """Return True when the status is optimal and every KKT residual <= ``tolerance``."""
        return self.optimal and max(self.residuals(problem)) <= tolerance
