"""The filter step's usual tick on a packed state, in one compiled pass.

A solved tick of :class:`~grasp_safety_filter.control.safety_filter.SafetyFilter` with the
OSQP backend is some thirty compiled or numpy calls of a microsecond or two each: each
family's rows, the finiteness and nominal checks, the backend's try of the previous tick's
active set (solve, clip, row check) and the residuals. :func:`packed_tick_metric` (for
the identity metric :func:`packed_tick`) runs the same kernels in the same order in one
call:

- no slip (:func:`~grasp_safety_filter.control.constraints.pyramid_kernel.
  pyramid_rows_packed`) and the box barriers (:func:`~grasp_safety_filter.control.
  constraints.box_kernel.box_barrier_rows_packed`) into ``A`` and ``lower``;
- with ``qp.metric: inverse_inertia``, the metric factor R of the state's M_h
  (:func:`~grasp_safety_filter.control.metric_kernel.inertia_factor`);
- :func:`~grasp_safety_filter.control.row_checks.all_finite` on the rows and u_nom;
- :func:`~grasp_safety_filter.control.row_checks.inside`: u_nom is the optimum;
- :func:`~grasp_safety_filter.control.working_set.clipped_optimum_on_working_set` on the
  backend's last active set (:meth:`~grasp_safety_filter.control.qp_solvers.osqp_backend.
  OSQPBackend.last_active_guess`), or with the metric :func:`~grasp_safety_filter.control.
  metric_kernel.metric_optimum_on_working_set` (its BLAS and LAPACK calls numpy's);
- :func:`~grasp_safety_filter.control.row_checks.residuals` at the answer.

so its answers are those of the unfused step, to the bit. Whatever is unusual (a family
without packed rows, a staged state, another backend) is not fused at all; a
tick whose u_nom or rows are not finite is done again by the unfused step (which raises or
falls back); a tick whose guess is not optimal continues with the backend's solve (without
trying the guess again).

On a tick the pass settles with the guess, the result's ``solve_time`` is the wall time of
the whole pass (rows, checks and the solve on the guess), as the solve alone is not timed
inside compiled code.
"""

from __future__ import annotations

from collections.abc import Sequence
import time
from typing import Any, NamedTuple, TYPE_CHECKING

import numpy as np

from grasp_safety_filter.control.constraints import ConstraintFamily, FrictionPyramid
from grasp_safety_filter.control.constraints.box_kernel import box_barrier_rows_packed
from grasp_safety_filter.control.constraints.pyramid_kernel import pyramid_rows_packed
from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.metric_kernel import (
    inertia_factor,
    metric_optimum_on_working_set,
    PAIRWISE_BLOCK,
)
from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.control.qp_solvers import (
    FEASIBILITY_TOLERANCE,
    Problem,
    Solution,
    SolutionStatus,
)
from grasp_safety_filter.control.qp_solvers.osqp_active_set import ACTIVE_SET_TOLERANCE
from grasp_safety_filter.control.row_checks import all_finite, inside, residuals
from grasp_safety_filter.control.working_set import clipped_optimum_on_working_set
from grasp_safety_filter.model.compiled import inline_kernel, kernel
from grasp_safety_filter.model.fortran_linalg import matrix_vector
from grasp_safety_filter.model.grasp_state import GraspState

if TYPE_CHECKING:
    from grasp_safety_filter.control.qp_solvers.osqp_backend import ActiveGuess, OSQPBackend
    from grasp_safety_filter.control.safety_filter import SafetyFilter

#: :func:`packed_tick`'s outcomes.
NOT_FINITE, NOT_SETTLED, SETTLED_ON_GUESS, NOMINAL = -1, 0, 1, 2


@kernel
def packed_tick(
    terms: np.ndarray,
    negative_faces: np.ndarray,
    pyramid: tuple[int, float, int],
    box_places: np.ndarray,
    box_rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    box_alpha: np.ndarray,
    h: np.ndarray,
    u_nom: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    nominal: tuple[np.ndarray, np.ndarray],
    guess: ActiveGuess,
    slack: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray, float]:
    """:func:`packed_tick_metric` for the identity metric (no metric arrays to pass in)."""
    empty, none = np.empty((0, 0)), np.empty(0)
    identity = (0, empty, none, empty, none, none, none)
    return _packed_tick(
        terms, negative_faces, pyramid, box_places, box_rows, box_alpha, h, u_nom, box, rows,
        nominal, identity, guess, slack,
    )


@kernel
def packed_tick_metric(
    terms: np.ndarray,
    negative_faces: np.ndarray,
    pyramid: tuple[int, float, int],
    box_places: np.ndarray,
    box_rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    box_alpha: np.ndarray,
    h: np.ndarray,
    u_nom: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    nominal: tuple[np.ndarray, np.ndarray],
    metric: tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    guess: ActiveGuess,
    slack: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray, float]:
    """Write the tick's rows, check them and u_nom, try the last active set (module doc).

    See :func:`_packed_tick` for the arguments.
    """
    return _packed_tick(
        terms, negative_faces, pyramid, box_places, box_rows, box_alpha, h, u_nom, box, rows,
        nominal, metric, guess, slack,
    )


# Inlined into each entry: no call that counts the references of two dozen arrays, and the
# identity entry's metric branch folds away.
@inline_kernel
def _packed_tick(
    terms: np.ndarray,
    negative_faces: np.ndarray,
    pyramid: tuple[int, float, int],
    box_places: np.ndarray,
    box_rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    box_alpha: np.ndarray,
    h: np.ndarray,
    u_nom: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    nominal: tuple[np.ndarray, np.ndarray],
    metric: tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    guess: ActiveGuess,
    slack: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray, float]:
    """Write the tick's rows, check them and u_nom, try the last active set (module doc).

    Args:
        terms: The packed state's buffer.
        negative_faces: :class:`FrictionPyramid`'s face normals, (n, rows per contact, 3)
            (point contacts) or (..., 4) (soft fingers, the torques' rows read too);
            (0, 1, 3) without no slip.
        pyramid: ``(force_start, normal_force_margin, first row)`` of the no-slip rows.
        box_places: Per box family, ``(x_start, x_dot_start, x_ddot_start, d, first row,
            first entry of its index, sign, h_offset and h, row count)``, (families, 7).
        box_rows: The families' ``index``, ``sign`` and ``h_offset``, concatenated.
        box_alpha: Per family ``(alpha_1 cubic, gain, alpha_2 cubic, gain)``, (families, 4).
        h: Out: the families' barrier values, concatenated.
        u_nom: Nominal torque, (m,), N·m.
        box: ``(u_min, u_max)``, (m,) each, N·m.
        rows: Out: the stacked ``A`` (k, m) and ``lower`` (k,); in: the hard QP's
            constraint values ``C_data`` (``A`` among them), checked finite.
        nominal: Out: the problem's cost ``g = -u_nom`` and the hard QP's ``nominal``.
        metric: ``(M_h's start in terms, R, R column-major, C R, y_nom, W, q)``: out, the
            metric factor R (m, m), the hard QP's ``q[:m] = W (-u_nom)`` (its W, (m, m),
            in) and the least-distance form in y (work); R of shape (0, 0): the identity.
        guess: :meth:`OSQPBackend.last_active_guess`: the last active set (q,) (empty: no
            guess), the hard least-distance rows ``[A; B]`` (k + 2m, m) and their lower
            bounds (rows ``:k`` written), and the working-set solve's scratch.
        slack: Out: ``A u - lower`` at the answer in ``[:k]``.

    Returns:
        ``(outcome, u, multipliers, smallest residual)``: :data:`NOMINAL` (u is u_nom),
        :data:`SETTLED_ON_GUESS`, :data:`NOT_SETTLED` (rows written and finite, u_nom
        outside, the guess absent or not optimal) or :data:`NOT_FINITE`.
    """
    A, lower, C_data = rows
    working_set, C, b, scratch = guess
    g, nominal_out = nominal
    u_min, u_max = box
    force_start, margin, start = pyramid
    pyramid_rows_packed(negative_faces, terms, force_start, margin, A, lower, start)
    index, sign, h_offset = box_rows
    for f in range(box_places.shape[0]):
        first, count = box_places[f, 5], box_places[f, 6]
        entries = slice(first, first + count)
        box_barrier_rows_packed(
            index[entries],
            sign[entries],
            h_offset[entries],
            terms,
            box_places[f, 0],
            box_places[f, 1],
            box_places[f, 2],
            box_places[f, 3],
            (box_alpha[f, 0] != 0.0, box_alpha[f, 1], box_alpha[f, 2] != 0.0, box_alpha[f, 3]),
            A,
            lower,
            box_places[f, 4],
            h[entries],
        )
    M_start, R, factor, rows_y, y_nom, W, q = metric
    m = u_nom.shape[0]
    with_metric = R.shape[0] > 0
    if with_metric and not inertia_factor(terms, M_start, R, factor):
        return NOT_FINITE, u_nom, np.empty(0), 0.0
    if not (all_finite(u_nom, u_min[:0]) and all_finite(C_data, lower)):
        return NOT_FINITE, u_nom, np.empty(0), 0.0
    for j in range(m):
        nominal_out[j] = u_nom[j]
        g[j] = -u_nom[j]
    if with_metric:
        matrix_vector(m, m, W, 0, m, 1, g, q)
    if inside(A, lower, u_nom, u_min, u_max):
        return NOMINAL, u_nom, np.empty(0), residuals(A, lower, u_nom, slack)
    if working_set.shape[0] == 0:
        return NOT_SETTLED, u_nom, np.empty(0), 0.0
    k = lower.shape[0]
    C[:k] = A
    b[:k] = lower
    y0 = -g  # -(-u_nom), u_nom to the bit: the backend's start
    if with_metric:
        outcome, u, multipliers = metric_optimum_on_working_set(
            C, b, working_set, (R, factor, rows_y, y_nom), y0, box, (C_data, lower),
            (ACTIVE_SET_TOLERANCE, FEASIBILITY_TOLERANCE), scratch,
        )
    else:
        outcome, u, multipliers = clipped_optimum_on_working_set(
            y0, C, b, working_set, ACTIVE_SET_TOLERANCE, u_min, u_max, A, lower,
            FEASIBILITY_TOLERANCE, scratch,
        )
    if outcome != 1:
        return NOT_SETTLED, u_nom, np.empty(0), 0.0
    return SETTLED_ON_GUESS, u, multipliers, residuals(A, lower, u, slack)


class FusedOutcome(NamedTuple):
    """A fused tick's answer.

    Attributes:
        u_nom: u_nom as a float array (the unfused step's checked copy).
        u: u* when settled (u_nom itself when nominal), else None: the rows and the
            problem's cost are written, and the backend's solve comes next.
        status: :attr:`FilterStatus.NOMINAL` or :attr:`FilterStatus.SOLVED`; None when not
            settled.
        solve_time: The pass's wall time when settled on the guess, else 0, s.
        computed: ``(slack, smallest residual)`` at u* (:meth:`ResultAssembler.result`).
    """

    u_nom: np.ndarray
    u: np.ndarray | None
    status: FilterStatus | None
    solve_time: float
    computed: tuple[np.ndarray, float]


class FusedTick:
    """:func:`packed_tick` for one filter: its arguments, laid out once per packed layout."""

    def __init__(
        self,
        families: Sequence[ConstraintFamily],
        starts: Sequence[int],
        problem: Problem,
        hard_qp: SafetyQP,
        backend: OSQPBackend,
        n_names: int,
        n_contacts: int,
    ) -> None:
        """Keep the filter's buffers; the layout's arguments are made on its first state.

        Args:
            families: The enabled families, in row order (each packed, see :meth:`of`).
            starts: Each family's first row.
            problem: The hard :class:`~grasp_safety_filter.control.qp_solvers.Problem`.
            hard_qp: The :class:`~grasp_safety_filter.control.qp.SafetyQP` on its buffers.
            backend: The OSQP backend.
            n_names: The result's rows, the box's included.
            n_contacts: n.
        """
        self._families = tuple(families)
        self._starts = tuple(starts)
        self._problem = problem
        self._backend = backend
        self._n_names = n_names
        self._m = problem.n_torques
        self._n = n_contacts
        self._rows = (problem.A, problem.lower, hard_qp.C_data)
        self._nominal = (problem.g, hard_qp.nominal)
        self._box = (problem.u_min, problem.u_max)
        self._hard_qp = hard_qp
        # The metric's buffers (R, R column-major, C R, y_nom); empty for the identity.
        R = problem.metric_factor
        m, rows = (0, 0) if R is None else (self._m, problem.n_rows + 2 * self._m)
        self._metric = (
            np.zeros((m, m)) if R is None else R, np.empty(m * m), np.empty((rows, m)),
            np.empty(m),
        )
        self._M_start = 0
        self._layout: Any = None
        self._arguments: tuple[Any, ...] = ()
        self._barriers: tuple[tuple[Any, slice], ...] = ()
        self._h_size = 0

    @classmethod
    def of(
        cls, safety_filter: SafetyFilter, starts: Sequence[int], n_names: int
    ) -> FusedTick | None:
        """Return a :class:`SafetyFilter`'s fused tick, or None where it does not apply.

        ``starts``: each family's first row; ``n_names``: the result's rows, the box's
        included (the filter's :class:`~grasp_safety_filter.control.result_assembly.
        ResultAssembler` layout).
        """
        families, problem = safety_filter.families, safety_filter.problem
        backend = safety_filter.backend
        if getattr(backend, 'last_active_guess', None) is None or problem.relaxed:
            return None
        if problem.n_torques > PAIRWISE_BLOCK:
            return None  # M_h's trace: numpy splits a longer sum (metric_kernel.numpy_sum)
        pyramids = [f for f in families if isinstance(f, FrictionPyramid)]
        boxes = [f for f in families if getattr(f, 'packed_fields', None) is not None]
        if not families or len(pyramids) + len(boxes) != len(families) or len(pyramids) > 1:
            return None
        hard_qp, n = safety_filter.hard_qp, len(safety_filter.contact_names)
        return cls(families, starts, problem, hard_qp, backend, n_names, n)

    def run(self, state: GraspState, u_nom: object) -> FusedOutcome | None:
        """Run the tick's pass; None when the unfused step must do the whole tick."""
        packed = getattr(state, 'packed_terms', None)
        if packed is None:
            return None
        terms, layout = packed
        if layout is not self._layout:
            if layout.n_joints != self._m or layout.n_contacts != self._n:
                return None  # the unfused step names the mismatch
            self._prepare(state, layout)
        try:
            u = np.array(u_nom, dtype=float)
        except (TypeError, ValueError):
            return None
        if u.shape != (self._m,) or terms.shape != (layout.size,):
            return None
        guess = self._backend.last_active_guess()
        h = np.empty(self._h_size)
        slack = np.empty(self._n_names)
        start = time.perf_counter()
        if self._problem.metric_factor is None:
            outcome, u_star, multipliers, smallest = packed_tick(
                terms, *self._arguments, h, u, self._box, self._rows, self._nominal, guess, slack,
            )
        else:
            hard_qp = self._hard_qp
            metric = (self._M_start, *self._metric, hard_qp.W.reshape(-1), hard_qp.q)
            outcome, u_star, multipliers, smallest = packed_tick_metric(
                terms, *self._arguments, h, u, self._box, self._rows, self._nominal, metric,
                guess, slack,
            )
        elapsed = time.perf_counter() - start
        if outcome == NOT_FINITE:
            return None
        for family, entries in self._barriers:
            family.remember_barrier(state, h[entries])
        computed = (slack, smallest)
        if outcome == NOMINAL:
            # u_nom is the optimum, with no active row (zero multipliers).
            self._backend.warm_start(Solution(u, SolutionStatus.OPTIMAL))
            return FusedOutcome(u, u, FilterStatus.NOMINAL, 0.0, computed)
        if outcome == SETTLED_ON_GUESS:
            R, _, rows_y, y_nom = self._metric
            in_y = None if self._problem.metric_factor is None else (R, rows_y, y_nom)
            solution = self._backend.accept_guess(u, u_star, multipliers, in_y)
            return FusedOutcome(u, solution.u, FilterStatus.SOLVED, elapsed, computed)
        if guess[0].shape[0]:
            self._backend.guess_rejected()  # the same rows, the same answer: not tried twice
        return FusedOutcome(u, None, None, 0.0, computed)

    def _prepare(self, state: GraspState, layout: Any) -> None:
        """Lay out :func:`packed_tick`'s arguments for a layout (the families check shapes)."""
        faces: np.ndarray = np.zeros((0, 1, 3))
        pyramid: tuple[int, float, int] = (0, 0.0, 0)
        places, index, sign, offset, alpha, barriers = [], [], [], [], [], []
        first = 0
        for family, start in zip(self._families, self._starts, strict=True):
            if isinstance(family, FrictionPyramid):
                faces, force_start, margin = family.packed_rows_arguments(state, layout)
                pyramid = (force_start, margin, start)
                continue
            i, s, o, starts, a = family.packed_rows_arguments(state, layout)
            count = i.shape[0]
            places.append((*starts, start, first, count))
            index.append(i)
            sign.append(s)
            offset.append(o)
            alpha.append([float(value) for value in a])
            barriers.append((family, slice(first, first + count)))
            first += count
        box_rows = (
            np.concatenate(index) if index else np.zeros(0, dtype=np.intp),
            np.concatenate(sign) if sign else np.zeros(0),
            np.concatenate(offset) if offset else np.zeros(0),
        )
        self._arguments = (
            faces,
            pyramid,
            np.array(places, dtype=np.intp).reshape(-1, 7),
            box_rows,
            np.array(alpha, dtype=float).reshape(-1, 4),
        )
        self._barriers = tuple(barriers)
        self._h_size = first
        self._M_start = layout.start('M_h')
        self._layout = layout
