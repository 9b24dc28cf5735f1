"""The grasp-constraint safety filter: the torque closest to u_nom that keeps the grasp safe.

Every tick (paper eq. 28)::

    u* = argmin_u ||u - u_nom||^2
         s.t.  no slip (friction pyramids), joint-limit ZCBFs, fingertip-workspace ZCBFs,
               u_min <= u <= u_max

The steps of :meth:`SafetyFilter.solve`:

1. Check u_nom (size, finite) and assemble the QP in place (:meth:`SafetyFilter.assemble`);
   a non-finite measured entry (:data:`MEASURED_STATE_FIELDS`) under a non-finite row
   raises ValueError naming it, before any solver call. Rows that are not finite although
   the measured state is (model terms overflowing at absurd but finite speeds or
   positions, or non-finite model terms) go to step 7 at once, with the families named.
2. If u_nom is inside the box and satisfies every row exactly, ``u* = u_nom`` (it is the
   optimum; no solver call). Status ``nominal``.
3. Otherwise, first the previous tick's active set: the rows move little from one tick to
   the next, so the rows active at last tick's u* are usually active at this one. The
   optimum with those rows held as equalities is one small linear solve
   (:func:`~grasp_safety_filter.control.least_distance.solve_on_working_set`); if it
   satisfies the KKT conditions the active-set method of step 5 stops on (every row and
   bound holds, multipliers nonnegative, same tolerance :data:`ACTIVE_SET_TOLERANCE`), it
   is u* exactly and OSQP is not called: status ``solved`` with no OSQP iterations, and
   OSQP's next warm start is this primal-dual pair. Otherwise the tick goes on as if the
   guess had not been tried. (No guess after a relaxed or fallback tick.)
4. OSQP solves the hard QP (set up once with a fixed sparsity pattern, warm-started from
   the previous tick's primal-dual solution), without polishing. Its ``(x, y)`` is
   accepted when it satisfies the KKT conditions to :data:`CERTIFICATE_TOLERANCE`; else
   the active set its multipliers name is tried as in step 3. Status ``solved``.
5. Otherwise the exact active-set method
   (:mod:`grasp_safety_filter.control.least_distance`) starts from OSQP's active set: it
   adds and drops rows until the KKT conditions hold: status ``solved`` if none was added
   or dropped, else ``solved_active_set``. Either way every row is then checked here to
   :data:`FEASIBILITY_TOLERANCE` (not taken from a solver's status).
6. If the hard QP is infeasible (the paper's Assumption 5 fails; proved by the active-set
   method, whatever OSQP said), the relaxed QP (:mod:`grasp_safety_filter.control.qp`:
   one slack per barrier row, weighted per family, actuator box hard) is solved the same
   way: OSQP, then the active-set method from OSQP's active set (with the slacks scaled by
   ``sqrt(w)`` the relaxed QP is a least-distance problem too). Status ``relaxed``; the
   families whose rows are violated at u* are named. The relaxed QP is first solved by
   the active-set method alone, from the rows that proved the hard QP infeasible (OSQP
   runs only if that does not end optimal). Relaxed ticks come in runs (the state that
   emptied the feasible set changes little in 1 ms): after a relaxed tick, the next one
   skips OSQP altogether, starts the infeasibility proof from the rows that gave the last
   one, and the relaxed QP from its active set.
7. If nothing gives a finite answer: the last accepted u* (or u_nom if there is none),
   clipped to the box. Status ``fallback_last_good`` / ``fallback_nominal``; the families
   whose rows are violated or not finite are named (``relaxed_families``), and
   ``max_violation`` is inf when a row is not finite.

Why steps 3 and 5: the filter's QPs are degenerate where it matters. Near a joint limit the
barrier rows of the same joint on the three fingers are nearly linearly dependent (all are
driven by the same 6-dof object motion), and OSQP's ADMM iterates then approach the optimum
very slowly (thousands of iterations to 1e-5 on the paper's scenario) while its active-set
guess is usually right after a few dozen. The dense active-set step on 9 variables costs
one small factorisation when the guess is right and makes the answer exact either way; and
the previous tick's active set is right on almost every tick of a smooth run, so most ticks
need no OSQP call at all.

OSQP settings (defaults): eps_abs = eps_rel = 1e-4, polishing off, max_iter = 50,
convergence checked every 5 iterations, warm start on (measured with ``grasp-bench``).
The tolerances only decide when ADMM hands its active set over (tighter ones add iterations
without improving the guess on degenerate problems); exactness comes from steps 3 to 5.
Polishing (OSQP's own active-set refinement) does the work of step 5 a second time: off,
the replayed paper run takes the same time and ends with the same answers, and OSQP 1.x
does not print its unconditional "Polishing not needed" line to stdout.
Infeasibility is decided by the active-set method, not by OSQP's certificate.

Relaxation priorities (defaults): slack weights 1e6 on no-slip and joint-limit rows, 1e3 on
fingertip-workspace rows. Slacks are normalised to torque-space distance (N·m), so the
weights read directly: giving up 1 mN·m of a no-slip or joint-limit row costs as much as
moving u by 1 N·m, of a workspace row as much as moving u by 31.6 mN·m. Dropping the object
or breaking a joint is worse than letting a contact roll towards the fingertip's edge.
"""

from __future__ import annotations

from collections.abc import ItemsView, Iterator, Mapping, Sequence, ValuesView
import dataclasses
from dataclasses import dataclass, field
from enum import Enum
import itertools
import time
from typing import Any, NamedTuple

import numpy as np
import osqp

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import (
    ActuatorLimits,
    ConstraintFamily,
    ConstraintRows,
    FingertipWorkspaceBarrier,
    FrictionPyramid,
    JointLimitBarrier,
)
from grasp_safety_filter.control.least_distance import (
    LeastDistanceSolution,
    LeastDistanceStatus,
    solve_least_distance,
    solve_on_working_set,
)
from grasp_safety_filter.control.qp import SafetyQP
from grasp_safety_filter.io.parameters import flatten_parameters
from grasp_safety_filter.io.schemas import SAFETY_FILTER_QP_PARAMETERS
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState

#: A row ``A u >= lower`` counts as satisfied when ``A u - lower >= -FEASIBILITY_TOLERANCE``
#: (in the row's unit: N for no slip, rad/s² for the barriers).
FEASIBILITY_TOLERANCE = 1e-6

#: Torque-space tolerance (N·m, per N·m of |u_nom|) of the KKT certificate of OSQP's solution.
CERTIFICATE_TOLERANCE = 1e-10

#: Distance tolerance (N·m, in torque space) of the exact active-set method.
ACTIVE_SET_TOLERANCE = 1e-10

#: Norm floor of a row in the guessed-active-set check (a null row: all zero coefficients).
_NULL_ROW_NORM = 1e-12

#: A row counts as active when ``A u - lower <= ACTIVE_TOLERANCE`` (and the actuator bound
#: when u is within it of the bound).
ACTIVE_TOLERANCE = 1e-6


#: Config field of each parameter.
_FIELDS: dict[str, str] = {
    'no_slip.enabled': 'no_slip_enabled',
    'no_slip.pyramid_faces': 'pyramid_faces',
    'no_slip.normal_force_margin': 'normal_force_margin',
    'joint_limits.enabled': 'joint_limits_enabled',
    'fingertip_workspace.enabled': 'fingertip_workspace_enabled',
    'barrier.alpha1.kind': 'alpha1_kind',
    'barrier.alpha1.gain': 'alpha1_gain',
    'barrier.alpha2.kind': 'alpha2_kind',
    'barrier.alpha2.gain': 'alpha2_gain',
    'relaxation.no_slip_weight': 'no_slip_weight',
    'relaxation.joint_limits_weight': 'joint_limits_weight',
    'relaxation.fingertip_workspace_weight': 'fingertip_workspace_weight',
    'osqp.eps_abs': 'eps_abs',
    'osqp.eps_rel': 'eps_rel',
    'osqp.max_iter': 'max_iter',
    'osqp.polish': 'polish',
}


@dataclass(frozen=True)
class SafetyFilterConfig:
    """Which constraints, how they decay, how they relax, how OSQP solves (see the parameters).

    Attributes:
        no_slip_enabled: Enforce the friction pyramids.
        pyramid_faces: Pyramid faces l_s (>= 3).
        normal_force_margin: Pyramid margin eps, N (>= 0).
        joint_limits_enabled: Enforce the joint-limit barriers.
        fingertip_workspace_enabled: Enforce the fingertip-workspace barriers.
        alpha1_kind, alpha1_gain: alpha_1 (``"cubic"`` or ``"linear"``, gain > 0).
        alpha2_kind, alpha2_gain: alpha_2 (same choices).
        no_slip_weight, joint_limits_weight, fingertip_workspace_weight: Slack weights of
            the relaxed QP (> 0), per (N·m)² of torque-space violation.
        eps_abs, eps_rel: OSQP tolerances (> 0).
        max_iter: OSQP iteration limit (>= 1).
        polish: OSQP solution polishing.
    """

    no_slip_enabled: bool = True
    pyramid_faces: int = 8
    normal_force_margin: float = 0.01
    joint_limits_enabled: bool = True
    fingertip_workspace_enabled: bool = True
    alpha1_kind: str = 'cubic'
    alpha1_gain: float = 1.0
    alpha2_kind: str = 'cubic'
    alpha2_gain: float = 1.0
    no_slip_weight: float = 1e6
    joint_limits_weight: float = 1e6
    fingertip_workspace_weight: float = 1e3
    eps_abs: float = 1e-4
    eps_rel: float = 1e-4
    max_iter: int = 50
    polish: bool = False

    def __post_init__(self) -> None:
        for spec in SAFETY_FILTER_QP_PARAMETERS:
            name = _FIELDS[spec.name]
            object.__setattr__(self, name, spec.validate(getattr(self, name)))

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SafetyFilterConfig:
        """Read the filter's parameters; missing ones take their defaults.

        Args:
            params: Values by dotted name (``{"no_slip.pyramid_faces": 8, ...}``) or as
                nested mappings (``{"no_slip": {"pyramid_faces": 8}}``); other names are
                ignored.

        Raises:
            ParameterError: A value has the wrong type or is out of range; the message names
                the parameter, what was expected and what was received.
        """
        flat = flatten_parameters(params)
        # Validated (and converted) by __post_init__, in the same order.
        return cls(
            **{
                _FIELDS[spec.name]: flat[spec.name]
                for spec in SAFETY_FILTER_QP_PARAMETERS
                if spec.name in flat
            }
        )

    def to_parameters(self) -> dict[str, Any]:
        """Return the configuration as ``{dotted parameter name: value}``."""
        return {
            spec.name: getattr(self, _FIELDS[spec.name]) for spec in SAFETY_FILTER_QP_PARAMETERS
        }

    @property
    def alpha1(self) -> ClassKFunction:
        """alpha_1 as a function."""
        return ClassKFunction(self.alpha1_kind, self.alpha1_gain)

    @property
    def alpha2(self) -> ClassKFunction:
        """alpha_2 as a function."""
        return ClassKFunction(self.alpha2_kind, self.alpha2_gain)

    def osqp_settings(self) -> dict[str, Any]:
        """Keyword settings for ``osqp.OSQP.setup``."""
        return {
            'verbose': False,
            'eps_abs': self.eps_abs,
            'eps_rel': self.eps_rel,
            'max_iter': self.max_iter,
            'polishing': self.polish,
            'warm_starting': True,
            # Check convergence every 5 iterations instead of OSQP's 25: the warm-started
            # problems converge in a few, and the exact step finishes those that do not.
            'check_termination': 5,
        }


#: The measured :class:`GraspState` fields (the arguments of ``GraspModel.state``); every
#: other field is a model term derived from them.
MEASURED_STATE_FIELDS: tuple[str, ...] = (
    'q',
    'dq',
    'p_object_in_palm',
    'R_object_to_palm',
    'twist_object',
)


class FilterStatus(str, Enum):
    """How :meth:`SafetyFilter.solve` obtained u* (the value is the status string)."""

    NOMINAL = 'nominal'
    """u_nom satisfies every row and the box: ``u* = u_nom``, no QP solved."""
    SOLVED = 'solved'
    """The hard QP's optimum, certified exactly by the KKT check: OSQP's answer, or the
    optimum on a guessed active set (the previous tick's, with no OSQP call and
    ``iterations == 0``, or OSQP's) satisfying the active-set method's KKT conditions."""
    SOLVED_ACTIVE_SET = 'solved_active_set'
    """The hard QP's optimum, reached by the active-set method from OSQP's guess."""
    RELAXED = 'relaxed'
    """The hard QP is infeasible: the relaxed QP's solution."""
    FALLBACK_LAST_GOOD = 'fallback_last_good'
    """No QP answer: the last solved or nominal u*, clipped to the box."""
    FALLBACK_NOMINAL = 'fallback_nominal'
    """No QP answer and no earlier u*: u_nom clipped to the box."""


class Margins(Mapping[str, float]):
    """Barrier value h per row name: a read-only mapping over a names tuple and a values array.

    Reads like the ``dict`` it stands for (``margins[name]``, iteration in row order,
    ``items()``, ``values()``, ``dict(margins)``, equality with a dict) without building
    one entry per row every tick. :attr:`names` and :attr:`array` give the rows in order.
    """

    __slots__ = ('_array', '_index', '_names')

    def __init__(
        self, names: tuple[str, ...], array: np.ndarray, index: Mapping[str, int] | None = None
    ) -> None:
        """Wrap ``array`` (shape (len(names),), made read-only) under ``names``.

        Args:
            names: Row names, distinct, in row order.
            array: The values, one per name.
            index: Position of each name (shared between views of the same rows); built
                from ``names`` when None.

        Raises:
            ValueError: ``array`` does not have one value per name.
        """
        if array.shape != (len(names),):
            raise ValueError(
                f'margins: expected {len(names)} values, got an array of shape {array.shape}'
            )
        array.setflags(write=False)
        self._names = names
        self._array = array
        self._index = index if index is not None else {n: i for i, n in enumerate(names)}

    @property
    def names(self) -> tuple[str, ...]:
        """Row names, in row order."""
        return self._names

    @property
    def array(self) -> np.ndarray:
        """The values in row order, shape (len(names),) (read-only)."""
        return self._array

    def __getitem__(self, name: str) -> float:
        return float(self._array[self._index[name]])

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def items(self) -> ItemsView[str, float]:
        """Return the ``(name, h)`` pairs in row order."""
        return _MarginItems(self)

    def values(self) -> ValuesView[float]:
        """Return the values h in row order."""
        return _MarginValues(self)

    def __repr__(self) -> str:
        return f'{type(self).__name__}({dict(self.items())!r})'


class _MarginItems(ItemsView[str, float]):
    """``Margins.items()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[tuple[str, float]]:
        return zip(self._mapping.names, self._mapping.array.tolist(), strict=True)


class _MarginValues(ValuesView[float]):
    """``Margins.values()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[float]:
        return iter(self._mapping.array.tolist())


@dataclass(frozen=True)
class FilterResult:
    """The outcome of one filter step.

    Attributes:
        u: The filtered torque u*, shape (m,), N·m: finite, inside the actuator box.
        status: How it was obtained (:class:`FilterStatus`; compares equal to its string).
        relaxed: True when u* is not certified to satisfy every row (status ``relaxed`` or
            a fallback); False for ``nominal``, ``solved`` and ``solved_active_set``.
        relaxed_families: Families with a row violated at u* by more than
            :data:`FEASIBILITY_TOLERANCE`, in stack order.
        margins: Barrier value h per row name (a read-only :class:`Margins` mapping): rad
            (joint limits, fingertip workspace), N (no slip, at the forces ``f_c(u*)``),
            N·m (actuator limits, at u*).
        active: Names of the rows with ``A u* - lower <= ACTIVE_TOLERANCE`` (violated rows
            included) and of the actuator bounds u* touches.
        solve_time: Wall time spent solving (OSQP update and solve, the active-set step,
            the relaxed QP when needed), s; 0 when no QP was solved.
        iterations: OSQP iterations (both QPs when relaxed); 0 when OSQP was not called
            (no QP solved, or the previous tick's active set certified).
        active_set_steps: Add/drop steps of the active-set method after OSQP's guess
            (0 when a guess was optimal).
        max_violation: ``max(0, max_r (lower_r - A_r u*))``, in the rows' own units.
    """

    u: np.ndarray
    status: FilterStatus
    relaxed: bool
    relaxed_families: tuple[str, ...]
    margins: Margins = field(repr=False)
    active: tuple[str, ...]
    solve_time: float
    iterations: int
    active_set_steps: int
    max_violation: float


#: The multipliers of an empty active set.
_NO_MULTIPLIERS = np.zeros(0)
_NO_MULTIPLIERS.setflags(write=False)

_NOT_CERTIFIED = frozenset(
    (FilterStatus.RELAXED, FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL)
)
_CONVERGED = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
_INFEASIBLE = (
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
)
_RELAXED_USABLE = (
    osqp.SolverStatus.OSQP_SOLVED,
    osqp.SolverStatus.OSQP_SOLVED_INACCURATE,
    osqp.SolverStatus.OSQP_MAX_ITER_REACHED,
)


class _OSQPSolution(NamedTuple):
    """What the filter reads of an OSQP solve: status code, iterations, primal x, dual y."""

    status: int
    iterations: int
    x: np.ndarray
    y: np.ndarray


class _OSQPProblem:
    """One OSQP problem, set up once with the QP's fixed pattern, then updated and solved."""

    def __init__(self, qp: SafetyQP, settings: dict[str, Any]) -> None:
        self._solver = osqp.OSQP()
        self._solver.setup(qp.P, qp.q, qp.C, qp.lower, qp.upper, **settings)

    def warm_start(self, x: np.ndarray, y: np.ndarray) -> None:
        """Start the next solve from the primal-dual pair ``(x, y)``."""
        self._solver.warm_start(x=x, y=y)

    def update(self, qp: SafetyQP) -> None:
        """Hand over the QP's current ``q``, ``lower`` and ``C`` values (same pattern)."""
        self._solver.update(q=qp.q, l=qp.lower, Ax=qp.C_data)

    def solve(self) -> _OSQPSolution:
        """Solve from the current warm start (never raises on a failed solve)."""
        solution = self._solver.solve(raise_error=False)
        return _OSQPSolution(
            solution.info.status_val, int(solution.info.iter), solution.x, solution.y
        )


class SafetyFilter:
    """CBF-QP safety filter over the grasp constraint families.

    Attributes:
        config: The configuration.
        joint_names, contact_names: Model joint and contact order.
        families: The enabled barrier families, in row order (no slip, joint limits,
            fingertip workspace).
        actuator_limits: The torque box (always enforced, never relaxed).
        row_names: Names of the barrier rows, in row order.
        hard_qp, relaxed_qp: The two QPs' buffers (the last assembled data).
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
    ) -> None:
        """Build the families and set both QPs up with OSQP.

        Args:
            config: What to enforce and how.
            joint_names: The m joint names, model order.
            contact_names: The n contact names, model order.
            q_min: Lower joint limits, shape (m,), rad.
            q_max: Upper joint limits, shape (m,), rad.
            u_min: Lower actuator limits, N·m (scalar or (m,)).
            u_max: Upper actuator limits, N·m (scalar or (m,)).
            mu: Friction coefficient(s), > 0 (scalar or (n,)).
            workspace: Fingertip box ``(a_min, a_max, b_min, b_max)``, rad.

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
        # Validated by every family that uses them; built here so that a bad argument is
        # reported even when its family is switched off.
        no_slip = FrictionPyramid(
            contact_names, mu, config.pyramid_faces, config.normal_force_margin
        )
        self.contact_names = no_slip.contact_names
        joint_limits = JointLimitBarrier(
            self.joint_names, q_min, q_max, config.alpha1, config.alpha2
        )
        try:
            a_min, a_max, b_min, b_max = workspace
        except (TypeError, ValueError):
            raise ValueError(
                f"'workspace': expected (a_min, a_max, b_min, b_max), got {workspace!r}"
            ) from None
        fingertip_workspace = FingertipWorkspaceBarrier(
            self.contact_names, a_min, a_max, b_min, b_max, config.alpha1, config.alpha2
        )
        chosen: list[tuple[ConstraintFamily, float]] = []
        if config.no_slip_enabled:
            chosen.append((no_slip, config.no_slip_weight))
        if config.joint_limits_enabled:
            chosen.append((joint_limits, config.joint_limits_weight))
        if config.fingertip_workspace_enabled:
            chosen.append((fingertip_workspace, config.fingertip_workspace_weight))
        self.families: tuple[ConstraintFamily, ...] = tuple(f for f, _ in chosen)
        self.row_names: tuple[str, ...] = tuple(n for f in self.families for n in f.names)
        k = len(self.row_names)
        sizes = [len(family.names) for family in self.families]
        ends = list(itertools.accumulate(sizes))
        self._slices = [slice(end - size, end) for size, end in zip(sizes, ends, strict=True)]
        self._row_family = np.repeat(np.arange(len(sizes), dtype=np.intp), sizes)
        weights = np.repeat(np.array([weight for _, weight in chosen], dtype=float), sizes)

        self._u_min = self.actuator_limits.lower
        self._u_max = self.actuator_limits.upper
        box = self.actuator_limits.rows()
        self.hard_qp = SafetyQP(m, k, self._u_min, self._u_max)
        self.relaxed_qp = SafetyQP(m, k, self._u_min, self._u_max, row_weights=weights)
        # The hard QP's rows for the active-set method: barrier rows (filled per tick), then
        # the box as ``u_j >= u_min,j`` and ``-u_j >= -u_max,j``.
        self._hard_rows = np.concatenate((np.zeros((k, m)), box.A))
        self._hard_lower = np.concatenate((np.zeros(k), box.lower))
        # Rows of the relaxed QP for the active-set method, variables (u, s~): barrier rows
        # [A, diag(d / sqrt(w))] (filled per tick), the box on u, s~ >= 0.
        self._relaxed_rows = np.zeros((2 * k + 2 * m, m + k))
        self._relaxed_rows[k : k + 2 * m, :m] = box.A
        self._relaxed_rows[k + 2 * m :, m:] = np.eye(k)
        self._relaxed_lower = np.concatenate((np.zeros(k), box.lower, np.zeros(k)))
        # The diagonal d / sqrt(w) of the barrier rows' slack block, a view (entry (r, m + r)).
        self._relaxed_slack_diagonal = self._relaxed_rows.reshape(-1)[
            m : m + k * (m + k + 1) : m + k + 1
        ]
        self._sqrt_row_weights = np.sqrt(self.relaxed_qp.row_weights)
        settings = config.osqp_settings()
        self._hard_solver = _OSQPProblem(self.hard_qp, settings)
        self._relaxed_solver = _OSQPProblem(self.relaxed_qp, settings)
        self._margin_names = (*self.row_names, *self.actuator_limits.names)
        self._margin_index = {name: i for i, name in enumerate(self._margin_names)}
        self._last_good_u: np.ndarray | None = None
        # OSQP keeps its last iterate as the next warm start; when a tick was settled
        # without it (nominal, active-set finisher), the exact primal-dual pair is kept here
        # as (u, active rows, multipliers), converted to OSQP's y only if OSQP runs next.
        self._pending_warm_start: tuple[np.ndarray, tuple[int, ...], np.ndarray] | None = None
        # Active-set rows (barrier rows, then the box) of the last hard optimum, tried first
        # next tick; None after a relaxed or fallback tick.
        self._last_active: tuple[int, ...] | None = None
        # After a relaxed tick: the rows that proved the hard QP infeasible and the relaxed
        # QP's active set, the next tick's starting points.
        self._infeasible_rows: tuple[int, ...] | None = None
        self._relaxed_active: tuple[int, ...] | None = None

    @classmethod
    def from_config(
        cls, grasp_model: Any, config: SafetyFilterConfig | None = None
    ) -> SafetyFilter:
        """Build the filter for a grasp model.

        Args:
            grasp_model: Anything with ``joint_names``, ``contact_names``,
                ``joint_lower_limits``, ``joint_upper_limits``, ``effort_limits`` (u_max;
                u_min = -u_max), ``friction_coefficient`` and ``fingertip_workspace``
                (``(a_min, a_max, b_min, b_max)``), e.g. a ``GraspModel``.
            config: The filter configuration (defaults if None).
        """
        effort = np.asarray(grasp_model.effort_limits, dtype=float)
        return cls(
            config if config is not None else SafetyFilterConfig(),
            joint_names=grasp_model.joint_names,
            contact_names=grasp_model.contact_names,
            q_min=grasp_model.joint_lower_limits,
            q_max=grasp_model.joint_upper_limits,
            u_min=-effort,
            u_max=effort,
            mu=grasp_model.friction_coefficient,
            workspace=tuple(grasp_model.fingertip_workspace),
        )

    @property
    def n_joints(self) -> int:
        """m, the number of joint torques."""
        return len(self.joint_names)

    def reset(self) -> None:
        """Forget the last accepted u* and the solvers' warm starts (e.g. a new run)."""
        self._last_good_u = None
        self._pending_warm_start = None
        self._last_active = None
        self._infeasible_rows = None
        self._relaxed_active = None
        m, k = self.n_joints, len(self.row_names)
        self._hard_solver.warm_start(x=np.zeros(m), y=np.zeros(k + m))
        self._relaxed_solver.warm_start(x=np.zeros(m + k), y=np.zeros(2 * k + m))

    def constraint_rows(self, state: GraspState) -> ConstraintRows:
        """Return the barrier rows ``A u >= lower`` at this state (a copy; no actuator box)."""
        self._assemble_rows(state)
        return ConstraintRows(
            self.hard_qp.A_rows.copy(), self.hard_qp.lower_rows.copy(), self.row_names
        )

    def margins(self, state: GraspState, u: np.ndarray) -> Margins:
        """Barrier values h per row name (families then actuator limits) at torque u."""
        values = np.empty(len(self._margin_names))
        with np.errstate(all='ignore'):
            self._write_margins(state, np.asarray(u, dtype=float), values)
        return Margins(self._margin_names, values, self._margin_index)

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
        u_nom = self._check_nominal(u_nom)
        rows_finite = self._assemble_rows(state)
        self.hard_qp.set_nominal(u_nom)
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
        u_nom, rows_finite = self.assemble(state, u_nom)
        A = self.hard_qp.A_rows
        lower = self.hard_qp.lower_rows
        # What a relaxed last tick left (set again only if this tick is relaxed too).
        infeasible_rows, self._infeasible_rows = self._infeasible_rows, None
        relaxed_active, self._relaxed_active = self._relaxed_active, None
        if not rows_finite:
            # A finite state whose rows overflowed (absurd magnitudes): no QP can help.
            return self._fallback(state, u_nom, A, lower, 0.0, 0)

        if (
            (u_nom >= self._u_min).all()
            and (u_nom <= self._u_max).all()
            and (A @ u_nom >= lower).all()
        ):
            self._last_good_u = u_nom
            # Optimal multipliers are zero when u_nom is feasible.
            self._pending_warm_start = (u_nom, (), _NO_MULTIPLIERS)
            self._last_active = ()
            return self._result(state, u_nom, FilterStatus.NOMINAL, A, lower, 0.0, 0)

        k = lower.shape[0]
        C, b = self._hard_rows, self._hard_lower
        C[:k] = A
        b[:k] = lower
        start = time.perf_counter()
        if self._last_active:
            # The rows move little from one tick to the next: last tick's active set is
            # usually this tick's, and then no OSQP call is needed.
            result = self._solve_on_guess(state, u_nom, self._last_active, A, lower, start, 0)
            if result is not None:
                return result

        if infeasible_rows is not None:
            # Last tick's hard QP was infeasible, and this one most likely is too: the
            # active-set method starts from the rows that proved it, without OSQP.
            exact = solve_least_distance(
                u_nom, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=infeasible_rows
            )
            if exact.status is LeastDistanceStatus.OPTIMAL:
                result = self._accept_exact(state, u_nom, exact, A, lower, start, 0)
                if result is not None:
                    return result
            elif exact.status is LeastDistanceStatus.INFEASIBLE:
                return self._solve_relaxed(state, u_nom, A, lower, exact, start, 0, relaxed_active)

        hard = self.hard_qp
        solver = self._hard_solver
        if self._pending_warm_start is not None:
            u_start, active_start, multipliers_start = self._pending_warm_start
            solver.warm_start(x=u_start, y=self._osqp_duals(active_start, multipliers_start))
            self._pending_warm_start = None
        solver.update(hard)
        solution = solver.solve()
        iterations = solution.iterations
        if solution.status in _CONVERGED:
            u = self._certified(solution.x, solution.y, u_nom, A, lower)
            if u is not None:
                solve_time = time.perf_counter() - start
                self._last_good_u = u
                self._last_active = self._working_set_guess(solution.y)
                return self._result(
                    state, u, FilterStatus.SOLVED, A, lower, solve_time, iterations
                )
        if solution.status in _INFEASIBLE or not np.isfinite(solution.y).all():
            guess: tuple[int, ...] = ()  # y is an infeasibility certificate, not multipliers
        else:
            guess = self._working_set_guess(solution.y)
            result = self._solve_on_guess(state, u_nom, guess, A, lower, start, iterations)
            if result is not None:
                return result
        exact = solve_least_distance(
            u_nom, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=guess
        )
        if exact.status is LeastDistanceStatus.OPTIMAL:
            result = self._accept_exact(state, u_nom, exact, A, lower, start, iterations)
            if result is not None:
                return result
        return self._solve_relaxed(
            state, u_nom, A, lower, exact, start, iterations, relaxed_active
        )

    # -- internals ---------------------------------------------------------------------

    def _solve_relaxed(
        self,
        state: GraspState,
        u_nom: np.ndarray,
        A: np.ndarray,
        lower: np.ndarray,
        exact: LeastDistanceSolution,
        start: float,
        iterations: int,
        relaxed_guess: tuple[int, ...] | None,
    ) -> FilterResult:
        """Solve the relaxed QP: the hard QP was not solved (``exact``: the attempt).

        When the hard QP was proved infeasible, the active-set method first starts without
        OSQP: from the last tick's relaxed active set (``relaxed_guess``) if the last tick
        was relaxed too (relaxed ticks come in runs, over which the active set changes
        little), else from the rows that proved the hard QP infeasible (the rows in
        conflict, which the relaxed optimum gives up). Else, or when that does not end
        optimal, OSQP's relaxed solution gives the start.
        """
        infeasible = exact.status is LeastDistanceStatus.INFEASIBLE
        if not infeasible:
            relaxed_guess = None
        elif not relaxed_guess:
            # Hard rows and the relaxed QP's u-rows share their numbering (barrier rows,
            # then the box).
            relaxed_guess = exact.active
        self._last_active = None
        # Next tick starts its infeasibility proof from the rows of this one.
        self._infeasible_rows = exact.active if infeasible else None

        relaxed = self.relaxed_qp
        relaxed.update(A, lower, u_nom)
        exact_relaxed = None
        solution = None
        if relaxed_guess:
            exact_relaxed = self._solve_relaxed_exactly(u_nom, relaxed_guess)
        if exact_relaxed is None or exact_relaxed.status is not LeastDistanceStatus.OPTIMAL:
            self._relaxed_solver.update(relaxed)
            solution = self._relaxed_solver.solve()
            iterations += solution.iterations
            # As for the hard QP, OSQP's active set is finished exactly: with s~ = sqrt(w) s
            # the relaxed QP is a least-distance problem in (u, s~) from (u_nom, 0).
            guess = self._working_set_guess(solution.y) if np.isfinite(solution.y).all() else ()
            exact_relaxed = self._solve_relaxed_exactly(u_nom, guess)
        solve_time = time.perf_counter() - start
        steps = exact.iterations + exact_relaxed.iterations
        u = None
        if exact_relaxed.status is LeastDistanceStatus.OPTIMAL:
            u = self._clip_finite(exact_relaxed.u)
            if u is not None:
                self._relaxed_active = exact_relaxed.active
        elif solution is not None and solution.status in _RELAXED_USABLE:
            u = self._clip_finite(solution.x)
        if u is None:
            self._pending_warm_start = (self.actuator_limits.clip(u_nom), (), _NO_MULTIPLIERS)
            return self._fallback(state, u_nom, A, lower, solve_time, iterations, steps)
        # The hard solver's iterate may have diverged on the infeasible problem: restart it
        # from this torque next tick.
        self._pending_warm_start = (u, (), _NO_MULTIPLIERS)
        return self._result(
            state, u, FilterStatus.RELAXED, A, lower, solve_time, iterations, steps
        )

    def _solve_on_guess(
        self,
        state: GraspState,
        u_nom: np.ndarray,
        guess: tuple[int, ...],
        A: np.ndarray,
        lower: np.ndarray,
        start: float,
        iterations: int,
    ) -> FilterResult | None:
        """Return the result for the optimum on a guessed active set if it is optimal, else None.

        The optimum with the guessed rows W held as equalities is one small linear solve
        (:func:`solve_on_working_set`). It is the hard QP's optimum when it satisfies the
        KKT conditions the active-set method stops on, to the same tolerance
        (:data:`ACTIVE_SET_TOLERANCE`, a torque-space distance): with ``n_i = ||C_i||``,
        every row and box bound holds (``(C_i u - b_i) / n_i >= -tol``), the rows of W hold
        with equality (``|C_i u - b_i| / n_i <= tol``) and their multipliers are
        nonnegative (``lambda_i n_i >= -tol``); stationarity holds by construction. Then
        every row is checked to :data:`FEASIBILITY_TOLERANCE`, as for the active-set
        method's answers. Status ``solved``.
        """
        if not guess:
            return None
        C, b = self._hard_rows, self._hard_lower
        guessed = solve_on_working_set(u_nom, C, b, guess)
        if guessed is None:
            return None
        u_guess, multipliers = guessed
        # Row norms, with a floor for null rows (a null row's distance is then its residual
        # scaled up: it holds only if its residual does).
        scale = np.maximum(np.sqrt(np.einsum('ij,ij->i', C, C)), _NULL_ROW_NORM)
        distance = (C @ u_guess - b) / scale
        rows = list(guess)
        if (
            distance.min() < -ACTIVE_SET_TOLERANCE
            or np.abs(distance.take(rows)).max() > ACTIVE_SET_TOLERANCE
            or (multipliers * scale.take(rows)).min() < -ACTIVE_SET_TOLERANCE
        ):
            return None
        u = self._clip_finite(u_guess)
        if u is None:
            return None
        residual = A @ u - lower
        if not residual.min(initial=0.0) >= -FEASIBILITY_TOLERANCE:
            return None
        solve_time = time.perf_counter() - start
        self._last_good_u = u
        self._last_active = guess
        self._pending_warm_start = (u, guess, multipliers)
        return self._result(
            state, u, FilterStatus.SOLVED, A, lower, solve_time, iterations, residual=residual
        )

    def _accept_exact(
        self,
        state: GraspState,
        u_nom: np.ndarray,
        exact: LeastDistanceSolution,
        A: np.ndarray,
        lower: np.ndarray,
        start: float,
        iterations: int,
    ) -> FilterResult | None:
        """Return the result for the active-set optimum, or None if u* fails a row check.

        Every row is checked here to :data:`FEASIBILITY_TOLERANCE`; the accepted working set
        is the next tick's first guess, and its multipliers OSQP's next warm start.
        """
        u = self._clip_finite(exact.u)
        if u is None or not (A @ u - lower >= -FEASIBILITY_TOLERANCE).all():
            return None
        solve_time = time.perf_counter() - start
        self._last_good_u = u
        self._last_active = exact.active
        self._pending_warm_start = (u, exact.active, exact.multipliers)
        status = FilterStatus.SOLVED if exact.iterations == 0 else FilterStatus.SOLVED_ACTIVE_SET
        return self._result(state, u, status, A, lower, solve_time, iterations, exact.iterations)

    def _check_nominal(self, u_nom: np.ndarray) -> np.ndarray:
        try:
            u = np.array(u_nom, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f'u_nom: expected {self.n_joints} numbers, got {u_nom!r}') from None
        if u.shape != (self.n_joints,):
            raise ValueError(f'u_nom: expected shape ({self.n_joints},), got {u.shape}')
        if not np.all(np.isfinite(u)):
            bad = np.flatnonzero(~np.isfinite(u))
            raise ValueError(
                f'u_nom: non-finite value {u[bad[0]]} for joint {self.joint_names[bad[0]]!r}'
            )
        return u

    def _assemble_rows(self, state: GraspState) -> bool:
        """Write every family's rows into the hard QP; False if they are not all finite."""
        if state.n_joints != self.n_joints or state.n_contacts != len(self.contact_names):
            raise ValueError(
                f'state: expected {self.n_joints} joints and {len(self.contact_names)} '
                f'contacts, got {state.n_joints} and {state.n_contacts}'
            )
        A = self.hard_qp.A_rows
        lower = self.hard_qp.lower_rows
        with np.errstate(all='ignore'):
            for family, rows in zip(self.families, self._slices, strict=True):
                block = family.rows(state)
                A[rows] = block.A
                lower[rows] = block.lower
        if np.isfinite(self.hard_qp.C_data).all() and np.isfinite(lower).all():
            return True
        self._raise_if_measured_not_finite(state)
        return False

    def _raise_if_measured_not_finite(self, state: GraspState) -> None:
        for name in MEASURED_STATE_FIELDS:
            value = getattr(state, name)
            arrays = (
                ((f'{name}.matrix', value.matrix), (f'{name}.offset', value.offset))
                if isinstance(value, AffineMap)
                else ((name, value),)
            )
            for label, array in arrays:
                bad = np.argwhere(~np.isfinite(np.asarray(array, dtype=float)))
                if bad.size:
                    index = tuple(int(i) for i in bad[0])
                    raise ValueError(
                        f'state.{label}: non-finite value {array[index]} at index '
                        f'{index[0] if len(index) == 1 else index}'
                    )

    def _certified(
        self, x: np.ndarray, y: np.ndarray, u_nom: np.ndarray, A: np.ndarray, lower: np.ndarray
    ) -> np.ndarray | None:
        """Certify OSQP's ``(x, y)``: x clipped to the box if it is optimal, else None.

        Optimal means: ``(x, y)`` satisfies the hard QP's KKT conditions to
        :data:`CERTIFICATE_TOLERANCE`.

        In torque space (N·m), with OSQP's sign convention (y < 0 at a lower bound) and
        ``n_i = ||A_i||``: every row holds (``slack_i = A_i u - lower_i >= -tol n_i``);
        barrier multipliers are <= 0; each row is either held with equality or has no
        multiplier (``min(|y_i| n_i, |slack_i| / n_i) <= tol``), and so is each box bound;
        and ``u - u_nom + A^T y_rows + y_box = 0`` to ``tol``. The QP is strictly convex:
        these KKT conditions make u the optimum to within about ``tol`` per active row.
        """
        k = lower.shape[0]
        u = x[: self.n_joints]
        y_rows, y_box = y[:k], y[k:]
        if not (np.isfinite(u).all() and np.isfinite(y).all()):
            return None
        tolerance = CERTIFICATE_TOLERANCE * (1.0 + float(np.abs(u_nom).max()))
        if k:
            norms = np.sqrt(np.einsum('ij,ij->i', A, A)) + 1e-300
            slack = (A @ u - lower) / norms
            if (
                slack.min() < -tolerance
                or y_rows.max() * norms.max() > tolerance
                or np.minimum(np.abs(y_rows) * norms, np.abs(slack)).max() > tolerance
            ):
                return None
        if np.abs(y_box).max() > tolerance:  # some torque at its bound: check which
            to_bound = np.where(y_box < 0.0, u - self._u_min, self._u_max - u)
            if np.minimum(np.abs(y_box), np.abs(to_bound)).max() > tolerance:
                return None
        if np.abs(u - u_nom + A.T @ y_rows + y_box).max() > tolerance:
            return None
        return np.minimum(np.maximum(u, self._u_min), self._u_max)

    def _working_set_guess(self, y: np.ndarray) -> tuple[int, ...]:
        """Rows OSQP's multipliers y call active, as active-set rows, largest |y| first.

        OSQP's constraints: barrier rows (k), the box (m), then, in the relaxed QP, the slack
        bounds (k). Active-set rows: barrier rows, box rows ``u_j >= u_min,j`` (k + 2 j) and
        ``-u_j >= -u_max,j`` (k + 2 j + 1), then slack bounds (k + 2 m + r). Multipliers
        below 1e-9 of the largest are noise.
        """
        k, m = len(self.row_names), self.n_joints
        magnitude = np.abs(y)
        threshold = 1e-9 * max(1.0, float(magnitude.max(initial=0.0)))
        rows = []
        for i in np.argsort(-magnitude):
            if magnitude[i] <= threshold:
                break
            if k <= i < k + m:
                rows.append(int(k + 2 * (i - k) + (1 if y[i] > 0.0 else 0)))
            elif y[i] < 0.0:  # barrier rows and slack bounds are lower-bounded only
                rows.append(int(i) if i < k else int(i + m))
        return tuple(rows)

    def _solve_relaxed_exactly(
        self, u_nom: np.ndarray, guess: tuple[int, ...]
    ) -> LeastDistanceSolution:
        """Solve the relaxed QP exactly by the active-set method, in ``(u, s~)``.

        ``min 1/2 ||u - u_nom||^2 + 1/2 ||s~||^2`` s.t. ``A u + (d / sqrt(w)) s~ >= lower``,
        the box, ``s~ >= 0`` (``s~ = sqrt(w) s``). Returns the solution with ``u`` only.
        """
        relaxed = self.relaxed_qp
        m, k = self.n_joints, len(self.row_names)
        C, b = self._relaxed_rows, self._relaxed_lower
        C[:k, :m] = relaxed.A_rows
        np.divide(relaxed.slack_scale, self._sqrt_row_weights, out=self._relaxed_slack_diagonal)
        b[:k] = relaxed.lower_rows
        start = np.concatenate((u_nom, np.zeros(k)))
        solution = solve_least_distance(
            start, C, b, tolerance=ACTIVE_SET_TOLERANCE, working_set=guess
        )
        return dataclasses.replace(solution, u=solution.u[:m])

    def _osqp_duals(self, active: tuple[int, ...], multipliers: np.ndarray) -> np.ndarray:
        """Map the active-set method's rows and multipliers to OSQP's y (hard QP).

        Finisher rows: barrier rows 0..k-1, then box rows ``u_j >= u_min,j`` (k + 2 j) and
        ``-u_j >= -u_max,j`` (k + 2 j + 1). OSQP: ``y_i < 0`` at a lower bound, ``> 0`` at
        an upper bound.
        """
        y = np.zeros(self.hard_qp.n_constraints)
        k = len(self.row_names)
        for row, value in zip(active, multipliers, strict=True):
            if row < k:
                y[row] = -value
            else:
                joint, upper = divmod(row - k, 2)
                y[k + joint] += value if upper else -value
        return y

    def _clip_finite(self, x: np.ndarray) -> np.ndarray | None:
        u = np.asarray(x[: self.n_joints], dtype=float)
        if not np.isfinite(u).all():
            return None
        return np.minimum(np.maximum(u, self._u_min), self._u_max)

    def _fallback(
        self,
        state: GraspState,
        u_nom: np.ndarray,
        A: np.ndarray,
        lower: np.ndarray,
        solve_time: float,
        iterations: int,
        active_set_steps: int = 0,
    ) -> FilterResult:
        self._last_active = None
        if self._last_good_u is not None:
            u = self.actuator_limits.clip(self._last_good_u)
            status = FilterStatus.FALLBACK_LAST_GOOD
        else:
            u = self.actuator_limits.clip(u_nom)
            status = FilterStatus.FALLBACK_NOMINAL
        return self._result(state, u, status, A, lower, solve_time, iterations, active_set_steps)

    def _write_margins(self, state: GraspState, u: np.ndarray, values: np.ndarray) -> None:
        """Write every family's barrier values at u, then the box margins, into ``values``."""
        for family, rows in zip(self.families, self._slices, strict=True):
            values[rows] = family.values(state, u).h
        # The box rows, joint by joint: u_j - u_min,j then u_max,j - u_j.
        k = len(self.row_names)
        np.subtract(u, self._u_min, out=values[k::2])
        np.subtract(self._u_max, u, out=values[k + 1 :: 2])

    def _result(
        self,
        state: GraspState,
        u: np.ndarray,
        status: FilterStatus,
        A: np.ndarray,
        lower: np.ndarray,
        solve_time: float,
        iterations: int,
        active_set_steps: int = 0,
        residual: np.ndarray | None = None,
    ) -> FilterResult:
        """Build the result for u*: margins, active rows, violated families.

        ``residual`` is ``A u - lower`` when the caller already has it.
        """
        u.setflags(write=False)
        k = len(self.row_names)
        values = np.empty(len(self._margin_names))
        # Residuals then box margins, side by side, for the active-row test.
        slack = np.empty(len(self._margin_names))
        with np.errstate(all='ignore'):
            if residual is None:
                residual = np.subtract(A @ u, lower, out=slack[:k])
            else:
                slack[:k] = residual
            self._write_margins(state, u, values)
        slack[k:] = values[k:]
        relaxed_families: tuple[str, ...] = ()
        worst = 0.0
        # min() is NaN when a row is: NaN rows count as violated, as in the test below.
        if k and not residual.min() >= -FEASIBILITY_TOLERANCE:
            violated = ~(residual >= -FEASIBILITY_TOLERANCE)
            relaxed_families = tuple(
                self.families[i].family for i in np.unique(self._row_family[violated])
            )
            worst = float(np.max(-residual))
        names = self._margin_names
        active = tuple([names[i] for i in np.flatnonzero(slack <= ACTIVE_TOLERANCE).tolist()])
        return FilterResult(
            u=u,
            status=status,
            relaxed=status in _NOT_CERTIFIED,
            relaxed_families=relaxed_families,
            margins=Margins(names, values, self._margin_index),
            active=active,
            solve_time=solve_time,
            iterations=iterations,
            active_set_steps=active_set_steps,
            max_violation=worst if worst == worst else float('inf'),  # NaN rows: unknown
        )
