"""Start-up advice: what the barrier families allow at the initial grasp, and the QP at rest.

At rest (``h_dot = 0``) a relative-degree-two barrier row ``h_ddot + alpha_1'(h) h_dot +
alpha_2(B) >= 0`` with ``B = h_dot + alpha_1(h)`` lets its coordinate accelerate towards the
bound at most at ``a = alpha_2(alpha_1(h))``, and approach it at most at ``v = alpha_1(h)``.
The time it takes to use the margin h is of the order of::

    tau = h / v + v / a          (linear alpha_i = k_i h: tau = 1 / k_1 + 1 / k_2)

A family whose rows have ``tau`` longer than a motion of the task (``frozen_time``, 1 s by
default) is practically frozen: the cubic ``alpha(h) = h^3`` at 0.15 rad leaves 3.4e-3 rad/s
and 3.8e-8 rad/s^2, tau = 9e4 s. The linear functions' tau does not depend on h, nor on its
unit (rad on a joint or a fingertip, m on an object face), so they are the suggestion:
``k_1 = k_2 = 2 / tau_target``.

The QP at rest: the largest ball of torques (radius ``rest_margin``, N·m) inside every row
``A_r u >= lower_r`` (rows normalised by ``|A_r|``) and the actuator box, a linear program
(scipy's HiGHS). ``rest_margin < 0``: no torque holds the grasp at rest within the actuator
limits; the rows that bind at the optimum name the conflict.

Held still: of the torques that satisfy every row and the actuator box at rest, the one that
accelerates the grasp least, in the kinetic-energy norm of hand and object together (Gauss's
least constraint; the ``acceleration`` QP metric of :mod:`~grasp_safety_filter.control.qp`)::

    u_still = argmin |a(u)|_W   subject to   A u >= lower,  u_min <= u <= u_max

Its largest joint acceleration ``still_acceleration`` is near zero when a squeeze inside the
friction cones and the actuator limits holds the grasp. Above :data:`STILL_ACCELERATION` no
admissible torque holds it still: it moves from the first tick, whatever the nominal
controller asks, and the rows binding at ``u_still`` say why (a friction cone at its apex, a
saturated actuator).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np
from scipy.optimize import linprog

from grasp_safety_filter.control.constraints.box_barrier import BoxBarrier
from grasp_safety_filter.control.filter_config import SafetyFilterConfig
from grasp_safety_filter.control.filter_result import ACTIVE_TOLERANCE
from grasp_safety_filter.control.qp import write_acceleration_factor
from grasp_safety_filter.control.qp_solvers import DAQPBackend, Problem, SolutionStatus
from grasp_safety_filter.model.grasp_state import GraspState

#: A family that needs longer than this to use its margins from rest is frozen, s.
FROZEN_TIME = 1.0
#: The filter's defaults, which the advice suggests to a frozen configuration, and their tau, s
#: (linear functions: 1/k1 + 1/k2).
_DEFAULTS = SafetyFilterConfig()
_DEFAULT_TAU = 1.0 / _DEFAULTS.alpha1_gain + 1.0 / _DEFAULTS.alpha2_gain
#: A grasp whose least joint acceleration at rest is above this cannot be held still, rad/s^2:
#: from rest a joint moves 0.5 rad in the first second.
STILL_ACCELERATION = 1.0
#: The families with a rest margin but no class-K function (their rows are not rates).
_SKIPPED = ('torque_rate',)
#: Rows whose |A_r| is below this (N·m^-1 in the row's unit) have no torque to act on.
_ZERO_ROW = 1e-12
#: Binding rows at the LP's optimum: |dual| above this.
_BINDING_DUAL = 1e-9


@dataclass(frozen=True)
class FamilyAdvice:
    """One barrier family's allowance at the initial margins, at rest.

    Attributes:
        family: The family's name.
        row: The row with the longest ``tau`` (of equal ones, the smallest margin).
        margin: Its h (rad, or m on an object face).
        speed: ``alpha_1(h)``: its largest approach speed, unit/s.
        acceleration: ``alpha_2(alpha_1(h))``: its largest acceleration from rest, unit/s^2.
        tau: ``h / speed + speed / acceleration``, s (inf at h <= 0).
        frozen_rows: How many of the family's rows have ``tau > frozen_time``.
        rows: The family's number of rows.
    """

    family: str
    row: str
    margin: float
    speed: float
    acceleration: float
    tau: float
    frozen_rows: int
    rows: int

    @property
    def frozen(self) -> bool:
        """Whether any row is practically frozen."""
        return self.frozen_rows > 0


@dataclass(frozen=True)
class StartupAdvice:
    """The advice at one state: family allowances, the QP at rest, suggested gains.

    Attributes:
        families: One entry per enabled relative-degree-two family.
        rest_margin: Radius of the largest torque ball inside every row at rest, N·m (< 0:
            infeasible at rest; NaN: the linear program failed).
        binding: The rows that limit ``rest_margin`` (barrier rows and actuator limits), or
            why it failed.
        suggestion: ``--set`` values of the filter's defaults where the configuration is
            the paper's (class-K functions, margins, object workspace, QP metric), when a
            family is frozen; empty otherwise.
        still_acceleration: u_still's largest joint acceleration at rest, rad/s^2 (NaN when
            the QP at rest is infeasible or not solved).
        still_object_acceleration: u_still's object acceleration, (linear m/s^2, angular
            rad/s^2) norms.
        still_binding: The rows binding at u_still (barrier rows and actuator limits).
    """

    families: tuple[FamilyAdvice, ...]
    rest_margin: float
    binding: tuple[str, ...]
    suggestion: dict[str, Any]
    still_acceleration: float = math.nan
    still_object_acceleration: tuple[float, float] = (math.nan, math.nan)
    still_binding: tuple[str, ...] = ()

    @property
    def frozen(self) -> tuple[str, ...]:
        """The frozen families' names."""
        return tuple(f.family for f in self.families if f.frozen)

    @property
    def verdict(self) -> str:
        """``undetermined``, ``infeasible``, ``moving``, ``frozen`` or ``ok`` (the first to apply).

        ``moving``: no admissible torque holds the grasp still (``still_acceleration`` above
        :data:`STILL_ACCELERATION`).
        """
        if math.isnan(self.rest_margin):
            return 'undetermined'
        if not self.rest_margin >= 0.0:
            return 'infeasible'
        if self.still_acceleration > STILL_ACCELERATION:
            return 'moving'
        if self.frozen:
            return 'frozen'
        return 'ok'

    @property
    def warns(self) -> bool:
        """Whether the advice is a warning (anything but ``ok``)."""
        return self.verdict != 'ok'

    def lines(self) -> list[str]:
        """Return the advice as log lines, one per family, the QP at rest and a suggestion."""
        lines = []
        for f in self.families:
            unit = _unit(f.row)
            state = (
                f'practically frozen ({f.frozen_rows} of {f.rows} rows)' if f.frozen else 'free'
            )
            lines.append(
                f'{f.family}: smallest margin {f.margin:.3g} {unit} ({f.row}): approach at '
                f'most {f.speed:.2g} {unit}/s, accelerate at most {f.acceleration:.2g} '
                f'{unit}/s^2 from rest, {f.tau:.2g} s to use it: {state}'
            )
        limiting = ', '.join(self.binding[:4]) + (' ...' if len(self.binding) > 4 else '')
        if self.verdict == 'undetermined':
            lines.append(f'QP at rest: not determined ({limiting})')
        elif self.verdict == 'infeasible':
            lines.append(
                f'QP at rest: infeasible by {-self.rest_margin:.3g} N·m: no torque within the '
                f'actuator limits holds the grasp (conflicting: {limiting})'
            )
        else:
            lines.append(
                f'QP at rest: feasible with a margin of {self.rest_margin:.3g} N·m (limited '
                f'by {limiting})'
            )
        if math.isfinite(self.still_acceleration):
            linear, angular = self.still_object_acceleration
            held = (
                'the least acceleration any admissible torque gives the grasp is '
                f'{self.still_acceleration:.2g} rad/s^2 on a joint, {linear:.2g} m/s^2 and '
                f'{angular:.2g} rad/s^2 on the object'
            )
            if self.verdict == 'moving':
                binding = ', '.join(self.still_binding[:6]) + (
                    ' ...' if len(self.still_binding) > 6 else ''
                )
                lines.append(
                    f'held still: no: {held} (bound by {binding}); the grasp moves from the '
                    'first tick whatever the nominal torque: choose another grasp, or raise the '
                    'effort limits if an actuator limit binds'
                )
            else:
                lines.append(f'held still: yes: {held}')
        if self.suggestion:
            settings = ' '.join(f'{k}={_text(v)}' for k, v in self.suggestion.items())
            lines.append(
                f'to let the frozen families move: {settings} (every family may then use its '
                f'margin in about {_DEFAULT_TAU:g} s, whatever its unit; the margins absorb what '
                'a control period overshoots; the contacts kept on their object faces)'
            )
        return lines


def rest_state(model: Any, state: GraspState) -> GraspState:
    """Return ``state``'s configuration at rest (joint and object velocities zero)."""
    return model.state(
        state.t,
        state.q,
        np.zeros_like(state.q),
        state.p_object_in_palm,
        state.R_object_to_palm,
        np.zeros(6),
    )


def startup_advice(
    safety_filter: Any,
    state: GraspState,
    frozen_time: float = FROZEN_TIME,
) -> StartupAdvice:
    """Return the advice at ``state`` (at rest: :func:`rest_state`) for a ``SafetyFilter``.

    Reads the filter's families and actuator limits; writes nothing of the filter's.
    """
    m = safety_filter.n_joints
    limits = safety_filter.actuator_limits
    families = [f for f in safety_filter.families if f.family not in _SKIPPED]
    blocks = [f.rows(state) for f in families] + [limits.rows(None)]
    A = np.vstack([b.A for b in blocks])
    lower = np.concatenate([b.lower for b in blocks])
    names = tuple(n for b in blocks for n in b.names)
    allowances = tuple(
        _family_advice(f, state, frozen_time) for f in families if isinstance(f, BoxBarrier)
    )
    rest_margin, binding = _rest_margin(A, lower, names, m)
    still: tuple[float, tuple[float, float], tuple[str, ...]] = (math.nan, (math.nan,) * 2, ())
    if rest_margin >= 0.0:
        still = _least_acceleration(state, A, lower, names, limits)
    frozen = any(f.frozen for f in allowances)
    suggestion = _suggestion(safety_filter.config) if frozen else {}
    return StartupAdvice(allowances, rest_margin, binding, suggestion, *still)


def _family_advice(family: BoxBarrier, state: GraspState, frozen_time: float) -> FamilyAdvice:
    """Return one relative-degree-two family's allowance at rest at ``state``."""
    h = np.asarray(family.values(state).h, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        speed = family.alpha1.value(h)
        acceleration = family.alpha2.value(speed)
        tau = np.where(h > 0.0, h / speed + speed / acceleration, math.inf)
    tau = np.where(np.isnan(tau), math.inf, tau)
    worst = int(np.lexsort((h, -tau))[0])  # the longest tau; of equal ones, the smallest h
    return FamilyAdvice(
        family.family,
        family.names[worst],
        float(h[worst]),
        float(speed[worst]),
        float(acceleration[worst]),
        float(tau[worst]),
        int(np.count_nonzero(tau > frozen_time)),
        len(family.names),
    )


def _rest_margin(
    A: np.ndarray, lower: np.ndarray, names: tuple[str, ...], m: int
) -> tuple[float, tuple[str, ...]]:
    """Return the largest t with a ball of radius t (N·m) inside ``A u >= lower``, and its rows.

    A row without torque (``|A_r| ~ 0``) holds for every torque or none: one with
    ``lower_r > 0`` makes the QP infeasible whatever the others (-inf, that row).
    """
    norms = np.linalg.norm(A, axis=1)
    live = norms > _ZERO_ROW
    dead = [n for n, ok, b in zip(names, live, lower, strict=True) if not ok and b > 0.0]
    if dead:
        return -math.inf, tuple(dead)
    # Variables (u, t): maximise t subject to -A_r u / |A_r| + t <= -lower_r / |A_r|. The
    # rows normalised: their norms span 1 (actuator limits) to ~1e6 (a light finger's joint
    # acceleration), which HiGHS does not solve unscaled.
    scale = norms[live, np.newaxis]
    A_ub = np.hstack((-A[live] / scale, np.ones_like(scale)))
    cost = np.zeros(m + 1)
    cost[-1] = -1.0
    bounds = [(None, None)] * (m + 1)
    result = linprog(cost, A_ub=A_ub, b_ub=-lower[live] / scale[:, 0], bounds=bounds)
    if result.status != 0:  # always feasible, bounded by the actuator box: numerical trouble
        return math.nan, (f'the linear program failed: {result.message}',)
    live_names = [n for n, ok in zip(names, live, strict=True) if ok]
    duals = np.asarray(result.ineqlin.marginals)
    binding = tuple(n for n, d in zip(live_names, duals, strict=True) if abs(d) > _BINDING_DUAL)
    return float(-result.fun), binding


def _suggestion(config: SafetyFilterConfig) -> dict[str, Any]:
    """Return the ``--set`` values of the defaults where ``config`` differs from them.

    The class-K functions always (they are frozen), the margins where smaller, the object
    workspace where off, the QP metric where another.
    """
    suggestion: dict[str, Any] = {}
    for alpha in ('alpha1', 'alpha2'):
        suggestion[f'barrier.{alpha}.kind'] = getattr(_DEFAULTS, f'{alpha}_kind')
        suggestion[f'barrier.{alpha}.gain'] = getattr(_DEFAULTS, f'{alpha}_gain')
    for family in ('joint_limits', 'fingertip_workspace'):
        default = getattr(_DEFAULTS, f'{family}_margin')
        if getattr(config, f'{family}_margin') < default:
            suggestion[f'{family}.margin'] = default
    if not config.object_workspace_enabled:
        suggestion['object_workspace.enabled'] = True
    if config.metric != _DEFAULTS.metric:
        suggestion['qp.metric'] = _DEFAULTS.metric
    return suggestion


def _least_acceleration(
    state: GraspState, A: np.ndarray, lower: np.ndarray, names: tuple[str, ...], limits: Any
) -> tuple[float, tuple[float, float], tuple[str, ...]]:
    """Return u_still's largest joint acceleration, its object's, and the rows active there.

    ``A``, ``lower`` and ``names`` are the rows at rest, the actuator limits' last. The cost
    ``|a(u)|_W^2`` is the acceleration metric ``(u - u_0)^T W (u - u_0)`` around
    ``u_0 = -W^-1 c (S_h^T M_h s_h + S_o^T M_o s_o)``, its unconstrained minimiser: the QP
    of one tick with u_0 for the nominal torque, solved by daqp. Active as in the filter's
    result: ``A_r u - lower_r <= ACTIVE_TOLERANCE``.
    """
    joint, obj = state.joint_acceleration, state.object_acceleration
    m = joint.matrix.shape[1]
    R = np.zeros((m, m))
    write_acceleration_factor(state.M_h, joint.matrix, obj.matrix, state.M_o, R)
    scale = float(np.trace(state.M_h)) / m
    pull = scale * (
        joint.matrix.T @ state.M_h @ joint.offset + obj.matrix.T @ state.M_o @ obj.offset
    )
    k = len(names) - len(limits.names)  # the box goes to the QP as bounds
    problem = Problem(
        R @ (R.T @ pull), A[:k], lower[:k], limits.lower, limits.upper, metric_factor=R
    )
    solution = DAQPBackend(problem, np.ones(k), {}).solve(problem)
    if solution.status != SolutionStatus.OPTIMAL:
        return math.nan, (math.nan, math.nan), (f'daqp: {solution.status.value}',)
    u = solution.u
    active = A @ u - lower <= ACTIVE_TOLERANCE
    a_object = obj.matrix @ u + obj.offset
    linear, angular = float(np.linalg.norm(a_object[:3])), float(np.linalg.norm(a_object[3:]))
    return (
        float(np.abs(joint.matrix @ u + joint.offset).max()),
        (linear, angular),
        tuple(n for n, hit in zip(names, active, strict=True) if hit),
    )


def _unit(row: str) -> str:
    """Return a barrier row's unit: m on an object face (``u_*``, ``v_*``), else rad."""
    label = row.rsplit('/', 1)[-1]
    return 'm' if label.startswith(('u_', 'v_')) else 'rad'


def _text(value: Any) -> str:
    """Return a parameter value as a parameter file writes it (``true``, ``10.0``)."""
    return str(value).lower() if isinstance(value, bool) else str(value)
