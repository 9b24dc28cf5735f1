"""The grasp-constraint safety filter: the torque closest to u_nom that keeps the grasp safe.

Every tick (paper eq. 28)::

    u* = argmin_u ||u - u_nom||^2
         s.t.  no slip (friction pyramids), joint-limit ZCBFs, fingertip-workspace ZCBFs,
               u_min <= u <= u_max

(``qp.metric: inverse_inertia`` measures ``u - u_nom`` in ``W = (tr(M_h)/m) M_h^-1``
instead, ``qp.metric: acceleration`` by the acceleration it gives the hand and the object,
:mod:`~grasp_safety_filter.control.qp`; the tick's M_h (and constrained dynamics) give W.)

:meth:`SafetyFilter.solve` reads top-down, one module per step: the rows
(:mod:`~grasp_safety_filter.control.filter_rows`, the families of
:mod:`~grasp_safety_filter.control.constraints`), the problem and its solve
(:mod:`~grasp_safety_filter.control.qp`, :mod:`~grasp_safety_filter.control.qp_solvers`),
the result (:mod:`~grasp_safety_filter.control.filter_result`).

1. **Rows.** Check u_nom (size, finite) and write every family's rows ``A u >= lower``
   (:meth:`SafetyFilter.assemble`); a non-finite measured entry
   (:data:`MEASURED_STATE_FIELDS`) under a non-finite row raises ValueError naming it,
   before any solver call. Rows that are not finite although the measured state is (model
   terms overflowing at absurd but finite speeds or positions) go to step 6 at once.
2. **Nominal.** If u_nom is inside the box and satisfies every row exactly, ``u* = u_nom``
   (it is the optimum; no solver call). Status ``nominal``.
3. **Problem and solve.** The hard :class:`~grasp_safety_filter.control.qp_solvers.Problem`
   (``g = -u_nom``, the rows, the box) goes to the backend chosen by ``qp.solver``
   (:mod:`~grasp_safety_filter.control.qp_solvers`: OSQP, its answer KKT-checked and
   finished by daqp when the check fails; or daqp), warm-started from its previous tick.
   An optimal answer is status ``solved``.
4. **Relaxed if infeasible.** Otherwise (the paper's Assumption 5 fails) the relaxed
   problem (one slack per barrier row, normalised to N·m and weighted per family; the
   actuator box stays hard) goes to the same backend. Status ``relaxed``; the families
   whose rows are violated at u* are named.
5. **Result.** u*, margins, active rows, violated families (:class:`FilterResult`). A
   backend returns an optimum only after its rows hold at u* to
   :data:`FEASIBILITY_TOLERANCE` (``Solution.row_violation``), whatever its solver said.
6. **Fallback.** If nothing gives a finite answer: the last accepted u* (or u_nom if there
   is none), clipped to the box. Status ``fallback_last_good`` / ``fallback_nominal``; the
   families whose rows are violated or not finite are named (``relaxed_families``), and
   ``max_violation`` is inf when a row is not finite.

Torque rate (``torque_rate.enabled``, off by default): rows ``|u_j - u_prev,j| <= du_max``
around the previous u* (:class:`~grasp_safety_filter.control.constraints.TorqueRateBound`;
vacuous after :meth:`SafetyFilter.reset` or a fallback), relaxed before any safety row: a
tick where only they gave is ``relaxed`` with ``relaxed_families == ("torque_rate",)``.

Relaxation priorities (defaults): slack weights 1e6 on no-slip and joint-limit rows, 1e3 on
fingertip-workspace rows. Slacks are normalised to torque-space distance (N·m; the
W-distance with ``qp.metric: inverse_inertia``), so the weights read directly: giving up
1 mN·m of a no-slip or joint-limit row costs as much as moving u by 1 N·m, of a workspace
row as much as moving u by 31.6 mN·m. Dropping the object or breaking a joint is worse
than letting a contact roll towards the fingertip's edge.
"""

from __future__ import annotations

from collections.abc import Sequence
import time
from typing import Any

import numpy as np

from grasp_safety_filter.control.constraints import (
    ActuatorLimits,
    ConstraintFamily,
    ConstraintRows,
    ObjectWorkspaceBarrier,
)
from grasp_safety_filter.control.filter_config import PAPER_CONFIG, SafetyFilterConfig
from grasp_safety_filter.control.filter_result import (
    ACTIVE_TOLERANCE,
    FilterResult,
    FilterStatus,
    Margins,
    ResultAssembler,
)
from grasp_safety_filter.control.filter_rows import (
    all_finite,
    checked_torque,
    FilterRows,
    inside,
    MEASURED_STATE_FIELDS,
    object_workspace_of,
    raise_if_measured_not_finite,
)
from grasp_safety_filter.control.qp import (
    ACCELERATION,
    IDENTITY,
    SafetyQP,
    write_acceleration_factor,
    write_inertia_factor,
)
from grasp_safety_filter.control.qp_solvers import (
    BACKENDS,
    FEASIBILITY_TOLERANCE,
    Problem,
    Solution,
    SolutionStatus,
)
from grasp_safety_filter.model.grasp_state import GraspState

__all__ = [
    'ACTIVE_TOLERANCE',
    'FEASIBILITY_TOLERANCE',
    'MEASURED_STATE_FIELDS',
    'PAPER_CONFIG',
    'FilterResult',
    'FilterStatus',
    'Margins',
    'SafetyFilter',
    'SafetyFilterConfig',
]

_FALLBACK = frozenset((FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL))


class SafetyFilter:
    """CBF-QP safety filter over the grasp constraint families.

    Attributes:
        config: The configuration.
        joint_names, contact_names: Model joint and contact order.
        families: The enabled barrier families, in row order (no slip, joint limits,
            fingertip workspace, object workspace, torque rate).
        torque_rate: The torque-rate family (None unless ``torque_rate.enabled``).
        actuator_limits: The torque box (always enforced, never relaxed).
        row_names: Names of the barrier rows, in row order.
        hard_qp: The hard QP in OSQP's form, the rows' buffer (the last assembled data).
        problem, relaxed_problem: The hard and relaxed problems on those buffers.
        backend: The QP backend (``qp.solver``).
    """

    def __init__(
        self,
        config: SafetyFilterConfig,
        joint_names: Sequence[str],
        contact_names: Sequence[str],
        q_min: Sequence[float] | np.ndarray,
        q_max: Sequence[float] | np.ndarray,
        u_min: float | Sequence[float] | np.ndarray,
        u_max: float | Sequence[float] | np.ndarray,
        mu: float | Sequence[float] | np.ndarray,
        workspace: tuple[float, float, float, float],
        object_workspace: ObjectWorkspaceBarrier | None = None,
        torsional_friction: float | Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """Build the families, the problems and the QP backend.

        Args:
            config: What to enforce and how.
            joint_names: The m joint names, model order.
            contact_names: The n contact names, model order.
            q_min: Lower joint limits, shape (m,), rad.
            q_max: Upper joint limits, shape (m,), rad.
            u_min: Lower actuator limits, N·m (scalar or (m,)).
            u_max: Upper actuator limits, N·m (scalar or (m,)).
            mu: Friction coefficient(s), > 0 (scalar or (n,)).
            workspace: Fingertip box ``(a_min, a_max, b_min, b_max)``, rad, each bound a
                scalar (every contact) or one per contact, (n,).
            object_workspace: The object-workspace family (its rows, same contacts);
                needed only with ``object_workspace_enabled``.
            torsional_friction: Soft fingers' torsional friction mu_t, > 0, m (scalar or
                (n,)): the no-slip rows also bound the torque about each contact normal,
                and ``contact_force`` has 4n rows; None: point contacts (3n rows).

        Raises:
            ValueError: A malformed argument; the message names it.
        """
        if not isinstance(config, SafetyFilterConfig):
            raise ValueError(
                f"'config': expected a SafetyFilterConfig, got {type(config).__name__}"
            )
        self.config = config
        self.actuator_limits = ActuatorLimits(joint_names, u_min, u_max)
        self.joint_names = self.actuator_limits.joint_names
        m = len(self.joint_names)
        self._rows = FilterRows(
            config, self.joint_names, contact_names, q_min, q_max, mu, workspace, object_workspace,
            torsional_friction,
        )
        self.contact_names = self._rows.contact_names
        self.torque_rate = self._rows.torque_rate
        self.families: tuple[ConstraintFamily, ...] = self._rows.families
        self.row_names = self._rows.names
        self._results = ResultAssembler(self._rows, self.actuator_limits)
        k = len(self.row_names)
        sizes = [len(family.names) for family in self.families]
        weights = np.repeat(np.array(self._rows.weights, dtype=float), sizes)

        self._u_min = self.actuator_limits.lower
        self._u_max = self.actuator_limits.upper
        metric = config.metric != IDENTITY
        self._acceleration_metric = config.metric == ACCELERATION
        self.hard_qp = SafetyQP(m, k, self._u_min, self._u_max, metric=metric)
        # The problems read the rows (and the metric factor) where _assemble_rows writes
        # them (no copy per tick); g = -u_nom is the hard QP's q only for the identity.
        self.problem = Problem(
            np.zeros(m) if metric else self.hard_qp.q,
            self.hard_qp.A_rows,
            self.hard_qp.lower_rows,
            self._u_min,
            self._u_max,
            metric_factor=self.hard_qp.metric_factor,
        )
        self.relaxed_problem = self.problem.with_slack(weights)
        self.backend = BACKENDS[config.solver](self.problem, weights, config.solver_settings())
        self._last_good_u: np.ndarray | None = None

    @classmethod
    def from_config(
        cls, grasp_model: Any, config: SafetyFilterConfig | None = None
    ) -> SafetyFilter:
        """Build the filter for a grasp model.

        Args:
            grasp_model: Anything with ``joint_names``, ``contact_names``,
                ``joint_lower_limits``, ``joint_upper_limits``, ``effort_limits`` (u_max;
                u_min = -u_max), ``friction_coefficient``, ``torsional_friction`` (None:
                point contacts) and ``fingertip_workspace``
                (``(a_min, a_max, b_min, b_max)``), e.g. a ``GraspModel``; with
                ``object_workspace.enabled`` a ``GraspModel`` (its contacts' object surfaces,
                :meth:`ObjectWorkspaceBarrier.for_model`).
            config: The filter configuration (defaults if None).
        """
        effort = np.asarray(grasp_model.effort_limits, dtype=float)
        config = config if config is not None else SafetyFilterConfig()
        return cls(
            config,
            joint_names=grasp_model.joint_names,
            contact_names=grasp_model.contact_names,
            q_min=grasp_model.joint_lower_limits,
            q_max=grasp_model.joint_upper_limits,
            u_min=-effort,
            u_max=effort,
            mu=grasp_model.friction_coefficient,
            workspace=tuple(grasp_model.fingertip_workspace),
            object_workspace=object_workspace_of(grasp_model, config),
            torsional_friction=grasp_model.torsional_friction,
        )

    @property
    def n_joints(self) -> int:
        """m, the number of joint torques."""
        return len(self.joint_names)

    def reset(self) -> None:
        """Forget the last accepted u* and the backend's warm starts (e.g. a new run)."""
        self._last_good_u = None
        if self.torque_rate is not None:
            self.torque_rate.forget()
        self.backend.reset()

    def load_kernels(self) -> None:
        """Load the compiled steps of rarer ticks now (a node's start-up, after a spare tick).

        The result's row checks, run on the last tick's rows; then reset.
        """
        self._results.load_kernels(self.problem.A, self.problem.lower)
        self.reset()

    def constraint_rows(self, state: GraspState) -> ConstraintRows:
        """Return the barrier rows ``A u >= lower`` at this state (a copy; no actuator box)."""
        self._assemble_rows(state)
        return ConstraintRows(
            self.hard_qp.A_rows.copy(), self.hard_qp.lower_rows.copy(), self.row_names
        )

    def margins(self, state: GraspState, u: np.ndarray) -> Margins:
        """Barrier values h per row name (families then actuator limits) at torque u."""
        return self._results.margins(state, u)

    def assemble(self, state: GraspState, u_nom: np.ndarray) -> tuple[np.ndarray, bool]:
        """Write this tick's hard QP into :attr:`hard_qp`: what :meth:`solve` does first.

        Checks u_nom, writes every family's rows ``A u >= lower`` and the cost
        ``q = -u_nom``; no solver is called (``hard_qp.dense()`` is then this tick's QP).

        Args:
            state: The grasp state of this tick.
            u_nom: Nominal torque, shape (m,), N·m.

        Returns:
            u_nom as a checked float array, and whether every row is finite (False only
            for a finite measured state whose model terms or rows are not finite).

        Raises:
            ValueError: As :meth:`solve`.
        """
        u_nom = checked_torque(u_nom, self.joint_names)
        rows_finite = self._assemble_rows(state)
        self.hard_qp.set_nominal(u_nom)
        if self.problem.metric_factor is not None:
            np.negative(u_nom, out=self.problem.g)
        return u_nom, rows_finite

    def solve(self, state: GraspState, u_nom: np.ndarray) -> FilterResult:
        """Filter one tick: the torque closest to u_nom satisfying the grasp constraints.

        Args:
            state: The grasp state of this tick.
            u_nom: Nominal torque, shape (m,), N·m.

        Returns:
            The filtered torque and how it was obtained. For any finite measured state
            (:data:`MEASURED_STATE_FIELDS`) the torque is finite and inside the actuator
            box: rows that overflow or model terms that are not finite give a fallback.

        Raises:
            ValueError: u_nom has the wrong size or a non-finite entry, the state has the
                wrong number of joints or contacts, or a measured field is not finite where
                the enabled families' rows are not; raised before any solver call.
        """
        result = self._solve_tick(state, u_nom)
        if self.torque_rate is not None:
            if result.status in _FALLBACK:
                self.torque_rate.forget()  # a fallback torque is no reference for the next
            else:
                self.torque_rate.remember(result.u, state.t)
        return result

    def _solve_tick(self, state: GraspState, u_nom: np.ndarray) -> FilterResult:
        """Run steps 1-6 of the module docstring for one tick (see :meth:`solve`)."""
        problem = self.problem
        u_nom, rows_finite = self.assemble(state, u_nom)
        if not rows_finite:
            # A finite state whose rows overflowed (absurd magnitudes): no QP can help.
            self.backend.warm_start(None)
            return self._fallback(state, u_nom, 0.0, 0)
        if inside(problem.A, problem.lower, u_nom, self._u_min, self._u_max):
            self._last_good_u = u_nom
            self.backend.warm_start(Solution(u_nom, SolutionStatus.OPTIMAL))
            return self._result(state, u_nom, FilterStatus.NOMINAL, 0.0, 0)

        start = time.perf_counter()
        hard = self.backend.solve(problem)
        if hard.optimal:
            self._last_good_u = hard.u
            return self._result(
                state, hard.u, FilterStatus.SOLVED, time.perf_counter() - start, hard.iterations
            )

        relaxed = self.backend.solve(self.relaxed_problem)
        solve_time = time.perf_counter() - start
        iterations = hard.iterations + relaxed.iterations
        if relaxed.optimal:
            return self._result(state, relaxed.u, FilterStatus.RELAXED, solve_time, iterations)
        return self._fallback(state, u_nom, solve_time, iterations)

    # -- internals ---------------------------------------------------------------------

    def _assemble_rows(self, state: GraspState) -> bool:
        """Write every family's rows into the hard QP; False if they are not all finite."""
        lower = self.problem.lower
        self._rows.write(state, self.problem.A, lower)
        metric_ok = True
        if self.problem.metric_factor is not None:
            try:
                if self._acceleration_metric:
                    write_acceleration_factor(
                        state.M_h,
                        state.joint_acceleration.matrix,
                        state.object_acceleration.matrix,
                        state.M_o,
                        self.problem.metric_factor,
                    )
                else:
                    write_inertia_factor(state.M_h, self.problem.metric_factor)
            except ValueError:
                metric_ok = False  # an M_h that overflowed: as rows that did
        if metric_ok and all_finite(self.hard_qp.C_data, lower):
            return True
        raise_if_measured_not_finite(state)
        return False

    def _fallback(
        self,
        state: GraspState,
        u_nom: np.ndarray,
        solve_time: float,
        iterations: int,
    ) -> FilterResult:
        if self._last_good_u is not None:
            u = self.actuator_limits.clip(self._last_good_u)
            status = FilterStatus.FALLBACK_LAST_GOOD
        else:
            u = self.actuator_limits.clip(u_nom)
            status = FilterStatus.FALLBACK_NOMINAL
        return self._result(state, u, status, solve_time, iterations)

    def _result(
        self,
        state: GraspState,
        u: np.ndarray,
        status: FilterStatus,
        solve_time: float,
        iterations: int,
    ) -> FilterResult:
        """Return the result for u* on this tick's rows (margins and active rows when read)."""
        rows = (self.problem.A, self.problem.lower)
        return self._results.result(state, u, status, rows, solve_time, iterations)
