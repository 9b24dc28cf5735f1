"""``grasp-bench``: how fast the filter is, on the paper's own filtered run.

1. **Record.** The paper's scenario runs closed loop (simulator, nominal controller and
   safety filter called directly, no messages) for ``--duration`` simulated seconds; every
   tick's plant state and u_nom are kept. Its wall time gives the filtered loop's
   real-time factor.
2. **Replay.** The recorded ticks are replayed in order through fresh instances, so every
   timing sees the same inputs and the filter the same warm starts as in the run. Per tick,
   each piece is timed on its own: the model terms (``GraspModel.state``), the nominal
   controller (reference sample and computed torque), the QP assembly
   (``SafetyFilter.assemble``), OSQP alone on the assembled hard QP (a second solver with the
   filter's settings: ``update`` + ``solve``, warm-started from its previous tick), the
   whole filter step (``SafetyFilter.solve``: assembly, solve, exact active-set step,
   checks and margins) and the whole filter-node tick (model terms + filter step).
3. **Other solvers.** The same hard QPs (``hard_qp.dense()`` of evenly spaced ticks) go to
   cvxpy (a fresh ``cvxpy.Problem`` per tick, as CBF research code is usually written: the
   default solver and OSQP with their default settings, and Clarabel with tight
   tolerances as an accurate reference) and to the dense active-set solver daqp through
   qpsolvers, each only if installed (``pip install grasp_safety_filter[bench]``). Their
   times are compared with the filter step on the same ticks and their solutions with ours
   (``max |Δu|``, on ticks whose hard QP is feasible).
4. **Closed loops.** Real-time factors (simulated seconds per wall second) of the nominal
   loop (simulator + nominal controller) and of the ROS-free runner recording to a bag.

Timings are wall-clock (``time.perf_counter``) with the garbage collector on, as in a
node. Nothing here asserts a time: the figures are for reading.

``grasp-bench --soak SECONDS`` runs the long-run benchmark instead (memory growth of the
recording runner, bag size per simulated second, memory of the analysis):
:mod:`grasp_safety_filter.soak`.
"""

from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
import importlib
import importlib.metadata
import json
import os
from pathlib import Path
import platform
import sys
import tempfile
import time
from typing import Any, NamedTuple
import warnings

import numpy as np
import osqp

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import Pose, ReferenceSource
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.config import SimConfig
from hand_sim_node.simulator import SimState, Simulator

#: Timed pieces of a tick, in table order: JSON key and label.
COMPONENTS: dict[str, str] = {
    'model_state': 'model terms (GraspModel.state)',
    'nominal_controller': 'nominal controller',
    'qp_assembly': 'QP assembly (SafetyFilter.assemble)',
    'osqp_solve': 'OSQP solve (update + solve)',
    'filter_qp_solve': 'filter QP solve (OSQP + active set)',
    'filter_step': 'filter step (SafetyFilter.solve)',
    'node_tick': 'filter node tick (model + filter step)',
}

#: Statuses whose u* solves the hard QP (the others are answers to an infeasible one).
CERTIFIED = frozenset((FilterStatus.NOMINAL, FilterStatus.SOLVED, FilterStatus.SOLVED_ACTIVE_SET))

#: Distribution packages whose versions the report lists.
VERSIONED_PACKAGES = ('numpy', 'scipy', 'osqp', 'cvxpy', 'qpsolvers', 'daqp', 'clarabel')


# --------------------------------------------------------------------------------------------
# The scenario and its recorded run


@dataclass(frozen=True)
class Scenario:
    """The paper's scenario as the three nodes read it from one parameter file.

    Attributes:
        config: The parameter file.
        model: The grasp model (the nodes each build their own; they are identical).
        sim_config: The simulator's configuration.
        nominal_config: The nominal controller's gains and reference.
        filter_config: The safety filter's configuration.
    """

    config: Path
    model: GraspModel
    sim_config: SimConfig
    nominal_config: NominalConfig
    filter_config: SafetyFilterConfig

    @classmethod
    def load(cls, config: Path, filter_overrides: dict[str, Any] | None = None) -> Scenario:
        """Read the scenario; ``filter_overrides`` replaces filter parameters by dotted name.

        Raises:
            ParameterError: A bad parameter file or override value.
            ValueError: An override names no safety-filter parameter.
        """
        known = SafetyFilterConfig().to_parameters()
        unknown = sorted(set(filter_overrides or {}) - set(known))
        if unknown:
            raise ValueError(
                f'filter override {unknown[0]!r}: expected one of {", ".join(sorted(known))}'
            )
        sim_params = load_node_parameters(config, HAND_SIM_NODE)
        filter_params = dict(load_node_parameters(config, SAFETY_FILTER_NODE))
        filter_params.update(filter_overrides or {})
        return cls(
            config=Path(config),
            model=GraspModel.from_parameters(sim_params),
            sim_config=SimConfig.from_parameters(sim_params),
            nominal_config=NominalConfig.from_parameters(
                load_node_parameters(config, NOMINAL_CONTROLLER_NODE)
            ),
            filter_config=SafetyFilterConfig.from_parameters(filter_params),
        )

    def safety_filter(self) -> SafetyFilter:
        """Build a fresh filter (no warm start)."""
        return SafetyFilter.from_config(self.model, self.filter_config)

    def reference(self, start: Tick | SimState) -> ReferenceSource:
        """Build the nominal controller's reference, started at ``start``'s pose and time."""
        return self.nominal_config.make_reference(
            Pose(start.p_object_in_palm, start.R_object_to_palm), start.t
        )


@dataclass(frozen=True, eq=False)
class Tick:
    """One control tick of the recorded run: the plant state, u_nom and the filter's u*."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray
    u_nom: np.ndarray
    u: np.ndarray
    status: FilterStatus


@dataclass(frozen=True)
class LoopRate:
    """A closed loop's speed.

    Attributes:
        simulated: Simulated time covered, s.
        wall: Wall time spent, s.
        steps: Simulator steps.
        stop_reason: Why the run ended (``"duration"`` when it ran to the end).
    """

    simulated: float
    wall: float
    steps: int
    stop_reason: str

    @classmethod
    def of(cls, simulator: Simulator, wall: float) -> LoopRate:
        """Return the rate of a loop that ran ``simulator`` from its start in ``wall`` s."""
        return cls(simulator.t, wall, simulator.step_index, simulator.stop_reason or 'duration')

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second (> 1: faster than real time)."""
        return self.simulated / self.wall if self.wall > 0.0 else float('inf')

    def to_json(self) -> dict[str, Any]:
        """Return the figures as a JSON object."""
        return {
            'simulated_s': self.simulated,
            'wall_s': self.wall,
            'steps': self.steps,
            'stop_reason': self.stop_reason,
            'real_time_factor': self.real_time_factor,
        }


def _closed_loop(
    scenario: Scenario, duration: float
) -> tuple[Simulator, NominalController, ReferenceSource, int]:
    """Build a closed loop's simulator (at the scenario's start), controller and reference.

    Returns:
        Them and the number of steps ``duration`` takes.
    """
    simulator = Simulator(scenario.model, scenario.sim_config)
    controller = NominalController(scenario.nominal_config)
    n_steps = max(1, round(duration / scenario.sim_config.time_step))
    return simulator, controller, scenario.reference(simulator.state), n_steps


def record_filtered_run(
    scenario: Scenario, duration: float
) -> tuple[list[Tick], LoopRate, np.ndarray]:
    """Run simulator + nominal controller + filter closed loop and keep every tick.

    Returns:
        The ticks, the loop's rate (its wall time includes the bookkeeping of the ticks,
        a few µs each) and the simulator step's wall time per tick, s.
    """
    model = scenario.model
    simulator, controller, reference, n_steps = _closed_loop(scenario, duration)
    safety_filter = scenario.safety_filter()
    ticks: list[Tick] = []
    step_times: list[float] = []
    wall_start = time.perf_counter()
    while simulator.stop_reason is None and simulator.step_index < n_steps:
        s = simulator.state
        state = model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
        u_nom = controller.compute(state, reference.sample(s.t)).u
        result = safety_filter.solve(state, u_nom)
        ticks.append(
            Tick(
                s.t,
                s.q,
                s.dq,
                s.p_object_in_palm,
                s.R_object_to_palm,
                s.twist_object,
                u_nom,
                result.u,
                result.status,
            )
        )
        step_start = time.perf_counter()
        simulator.step(result.u)
        step_times.append(time.perf_counter() - step_start)
    rate = LoopRate.of(simulator, time.perf_counter() - wall_start)
    return ticks, rate, np.array(step_times)


def nominal_loop_rate(scenario: Scenario, duration: float) -> LoopRate:
    """Real-time factor of simulator + nominal controller (the paper's unfiltered run)."""
    model = scenario.model
    simulator, controller, reference, n_steps = _closed_loop(scenario, duration)
    wall_start = time.perf_counter()
    while simulator.stop_reason is None and simulator.step_index < n_steps:
        s = simulator.state
        state = model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
        simulator.step(controller.compute(state, reference.sample(s.t)).u)
    return LoopRate.of(simulator, time.perf_counter() - wall_start)


def runner_loop_rate(config: Path, duration: float, time_step: float) -> LoopRate:
    """Real-time factor of the ROS-free runner's filtered run, recording every message to a bag.

    Times :func:`grasp_safety_filter.runner.record_run` (the loop and the bag, not the
    analysis and figures :func:`~grasp_safety_filter.runner.run` adds afterwards).
    """
    from grasp_safety_filter.runner import record_run, RunOptions

    with tempfile.TemporaryDirectory(prefix='grasp-bench-') as directory:
        options = RunOptions(config, mode='filtered', duration=duration)
        wall_start = time.perf_counter()
        recording = record_run(options, Path(directory) / 'bag')
        wall = time.perf_counter() - wall_start
    steps = round(recording.t_end / time_step)
    return LoopRate(recording.t_end, wall, steps, recording.stop_reason or 'duration')


# --------------------------------------------------------------------------------------------
# Replay: the filter's pieces, tick by tick


class DenseQP(NamedTuple):
    """A hard QP ``min 1/2 x^T P x + q^T x  s.t.  lower <= C x <= upper`` (dense copies)."""

    P: np.ndarray
    q: np.ndarray
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


@dataclass(frozen=True, eq=False)
class Replay:
    """What the replay measured.

    Attributes:
        times: Wall time per tick and piece (keys of :data:`COMPONENTS`), s. Each array has
            one entry per replayed tick, except ``filter_qp_solve`` (ticks where the filter
            solved a QP, i.e. not ``nominal``).
        u: The filter's u* per tick, shape (ticks, m).
        status: The filter's status per tick.
        osqp_iterations: Iterations of the stand-alone OSQP solve per tick.
        osqp_status: Its status per tick.
        filter_iterations: OSQP iterations inside the filter per tick (0 when none ran).
        active_set_steps: Add/drop steps of the filter's active-set method per tick.
        filter_qp_solve_time: The filter's own solve time per tick (``FilterResult.solve_time``:
            OSQP and the active-set step; 0 on ``nominal`` ticks), s.
        qps: The hard QP of the ticks in ``qp_ticks``.
        qp_ticks: Indices (into the replayed ticks) of :attr:`qps`.
        max_replay_deviation: ``max |u*_replay - u*_recorded|``, N·m (0 when the replay
            reproduces the run).
    """

    times: dict[str, np.ndarray]
    u: np.ndarray
    status: list[FilterStatus]
    osqp_iterations: np.ndarray
    osqp_status: list[str]
    filter_iterations: np.ndarray
    active_set_steps: np.ndarray
    filter_qp_solve_time: np.ndarray
    qps: list[DenseQP]
    qp_ticks: np.ndarray
    max_replay_deviation: float


def _standalone_osqp(safety_filter: SafetyFilter) -> osqp.OSQP:
    """Set up an OSQP solver like the filter's hard-QP solver (same pattern and settings)."""
    hard = safety_filter.hard_qp
    solver = osqp.OSQP()
    solver.setup(
        hard.P, hard.q, hard.C, hard.lower, hard.upper, **safety_filter.config.osqp_settings()
    )
    return solver


def replay(scenario: Scenario, ticks: Sequence[Tick], qp_ticks: Sequence[int] = ()) -> Replay:
    """Replay ``ticks`` in order through fresh instances, timing each piece of every tick.

    Args:
        scenario: The scenario the ticks were recorded on.
        ticks: The ticks, from the start of the run (the filter's warm starts chain).
        qp_ticks: Indices of the ticks whose hard QP to keep (for other solvers).
    """
    if not ticks:
        raise ValueError('replay: expected at least one tick, got none')
    model = scenario.model
    controller = NominalController(scenario.nominal_config)
    safety_filter = scenario.safety_filter()
    solver = _standalone_osqp(safety_filter)
    hard = safety_filter.hard_qp
    reference = scenario.reference(ticks[0])
    wanted = set(qp_ticks)
    clock = time.perf_counter
    n = len(ticks)
    times = {key: np.zeros(n) for key in COMPONENTS if key != 'filter_qp_solve'}
    qp_solve_times = np.zeros(n)
    u = np.zeros((n, model.n_joints))
    status: list[FilterStatus] = []
    osqp_iterations = np.zeros(n, dtype=int)
    osqp_status: list[str] = []
    filter_iterations = np.zeros(n, dtype=int)
    active_set_steps = np.zeros(n, dtype=int)
    qps: list[DenseQP] = []
    kept: list[int] = []
    for i, tick in enumerate(ticks):
        # The node's tick: model terms then the filter step, back to back.
        t0 = clock()
        state = model.state(
            tick.t,
            tick.q,
            tick.dq,
            tick.p_object_in_palm,
            tick.R_object_to_palm,
            tick.twist_object,
        )
        t1 = clock()
        result = safety_filter.solve(state, tick.u_nom)
        t2 = clock()
        times['model_state'][i] = t1 - t0
        times['filter_step'][i] = t2 - t1
        times['node_tick'][i] = t2 - t0
        # The other pieces leave the filter's state alone: the nominal controller is
        # stateless, and assembling again writes the same QP the step just solved.
        t0 = clock()
        controller.compute(state, reference.sample(tick.t))
        t1 = clock()
        safety_filter.assemble(state, tick.u_nom)
        t2 = clock()
        solver.update(q=hard.q, l=hard.lower, Ax=hard.C_data)
        solution = solver.solve(raise_error=False)
        t3 = clock()
        times['nominal_controller'][i] = t1 - t0
        times['qp_assembly'][i] = t2 - t1
        times['osqp_solve'][i] = t3 - t2
        qp_solve_times[i] = result.solve_time
        u[i] = result.u
        status.append(result.status)
        osqp_iterations[i] = solution.info.iter
        osqp_status.append(str(solution.info.status))
        filter_iterations[i] = result.iterations
        active_set_steps[i] = result.active_set_steps
        if i in wanted:
            qps.append(DenseQP(*hard.dense()))
            kept.append(i)
    solved_a_qp = np.array([s is not FilterStatus.NOMINAL for s in status], dtype=bool)
    times['filter_qp_solve'] = qp_solve_times[solved_a_qp]
    recorded = np.array([tick.u for tick in ticks]).reshape(n, model.n_joints)
    return Replay(
        times={key: times[key] for key in COMPONENTS},
        u=u,
        status=status,
        osqp_iterations=osqp_iterations,
        osqp_status=osqp_status,
        filter_iterations=filter_iterations,
        active_set_steps=active_set_steps,
        filter_qp_solve_time=qp_solve_times,
        qps=qps,
        qp_ticks=np.array(kept, dtype=int),
        max_replay_deviation=float(np.abs(u - recorded).max(initial=0.0)),
    )


# --------------------------------------------------------------------------------------------
# The same QPs through other solvers


class SolverInput(NamedTuple):
    """A QP in the general form ``min 1/2 x^T P x + q^T x  s.t.  G x <= h,  lb <= x <= ub``."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray


def general_form(qp: DenseQP) -> SolverInput:
    """Rewrite ``lower <= C x <= upper`` as ``G x <= h`` and bounds on x.

    Rows of C with a single nonzero entry equal to 1 are bounds on their variable; every
    other row gives ``-C_r x <= -lower_r`` and/or ``C_r x <= upper_r`` for its finite sides.
    """
    n = qp.q.size
    lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
    general = []
    for r, row in enumerate(qp.C):
        (nonzero,) = np.nonzero(row)
        if nonzero.size == 1 and row[nonzero[0]] == 1.0:
            j = nonzero[0]
            lb[j] = max(lb[j], qp.lower[r])
            ub[j] = min(ub[j], qp.upper[r])
        else:
            general.append(r)
    rows = qp.C[general]
    lower, upper = qp.lower[general], qp.upper[general]
    has_lower, has_upper = np.isfinite(lower), np.isfinite(upper)
    G = np.concatenate((-rows[has_lower], rows[has_upper]))
    h = np.concatenate((-lower[has_lower], upper[has_upper]))
    return SolverInput(qp.P, qp.q, G, h, lb, ub)


class ExternalAnswer(NamedTuple):
    """One external solve: the solution (None if none was returned), status and solver."""

    x: np.ndarray | None
    status: str
    solver: str
    solver_time: float | None


@dataclass(frozen=True)
class ExternalSolver:
    """Another way to solve the same QP.

    Attributes:
        key: JSON key.
        label: Table label.
        solve: The solve, or None when the packages it needs are not installed.
        unavailable: Why it is skipped (None when available).
    """

    key: str
    label: str
    solve: Callable[[SolverInput], ExternalAnswer] | None
    unavailable: str | None = None


def _cvxpy_solve(solver: str | None, **options: float) -> Callable[[SolverInput], ExternalAnswer]:
    cp = importlib.import_module('cvxpy')
    if solver is not None and solver not in cp.installed_solvers():
        raise ImportError(f'cvxpy has no {solver} solver installed')

    def solve(qp: SolverInput) -> ExternalAnswer:
        # Built anew every tick, as a CBF-QP written with cvxpy usually is.
        x = cp.Variable(qp.q.size)
        problem = cp.Problem(
            cp.Minimize(0.5 * cp.quad_form(x, qp.P) + qp.q @ x),
            [qp.G @ x <= qp.h, x >= qp.lb, x <= qp.ub],
        )
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')  # "solution may be inaccurate": counted below
                problem.solve() if solver is None else problem.solve(solver=solver, **options)
        except cp.error.SolverError:
            return ExternalAnswer(None, 'solver_error', solver or 'default', None)
        stats = problem.solver_stats
        value = x.value
        if value is not None and not np.isfinite(value).all():
            value = None
        return ExternalAnswer(
            None if value is None else np.array(value),
            str(problem.status),
            stats.solver_name if stats is not None else (solver or 'default'),
            stats.solve_time if stats is not None else None,
        )

    return solve


def _qpsolvers_solve(solver: str) -> Callable[[SolverInput], ExternalAnswer]:
    qpsolvers = importlib.import_module('qpsolvers')
    if solver not in qpsolvers.available_solvers:
        raise ImportError(f'qpsolvers has no {solver} backend installed')

    def solve(qp: SolverInput) -> ExternalAnswer:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            x = qpsolvers.solve_qp(qp.P, qp.q, qp.G, qp.h, lb=qp.lb, ub=qp.ub, solver=solver)
        if x is None or not np.isfinite(x).all():
            return ExternalAnswer(None, 'no_solution', solver, None)
        return ExternalAnswer(np.asarray(x, dtype=float), 'solved', solver, None)

    return solve


#: Clarabel's tolerances for the accurate cvxpy reference. An interior-point method stops
#: at a duality gap eps, and on a least-distance problem that leaves ``||u - u*|| ~ sqrt(2 eps)``:
#: its default gap 1e-8 allows about 1e-4 N·m, 1e-12 about 1e-6. (A feasibility tolerance
#: below 1e-10 makes it stall on this scenario's ill-conditioned QPs.)
CLARABEL_TIGHT = {'tol_gap_abs': 1e-12, 'tol_gap_rel': 1e-12, 'tol_feas': 1e-10}

#: The external solvers: key, label, factory of the solve function. The first two use
#: their defaults, as research code usually does; the last two are accurate references.
EXTERNAL_SOLVERS: tuple[
    tuple[str, str, Callable[[], Callable[[SolverInput], ExternalAnswer]]], ...
] = (
    ('cvxpy', 'cvxpy, default solver', lambda: _cvxpy_solve(None)),
    ('cvxpy_osqp', 'cvxpy + OSQP', lambda: _cvxpy_solve('OSQP')),
    (
        'cvxpy_clarabel',
        'cvxpy + Clarabel (tight)',
        lambda: _cvxpy_solve('CLARABEL', **CLARABEL_TIGHT),
    ),
    ('daqp', 'daqp (qpsolvers)', lambda: _qpsolvers_solve('daqp')),
)


def external_solvers() -> list[ExternalSolver]:
    """Every solver of :data:`EXTERNAL_SOLVERS`, with the reason when it is not installed."""
    solvers = []
    for key, label, factory in EXTERNAL_SOLVERS:
        try:
            solvers.append(ExternalSolver(key, label, factory()))
        except ImportError as error:
            reason = f'not installed ({error}); pip install grasp_safety_filter[bench]'
            solvers.append(ExternalSolver(key, label, None, reason))
    return solvers


def run_external(
    solver: ExternalSolver,
    qps: Sequence[DenseQP],
    ours: np.ndarray,
    certified: np.ndarray,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Solve every QP with ``solver``; compare with our u* where ours is certified.

    Args:
        solver: An available external solver.
        qps: The hard QPs.
        ours: Our u* per QP, shape (len(qps), m).
        certified: Per QP, True when our u* solves it (the hard QP is feasible), False when
            the filter found it infeasible.

    Returns:
        Wall time per QP (s), and the comparison: statuses, solver name, ``max_abs_du``
        (N·m, over ``compared`` QPs that both solved), ``missing`` (feasible QPs it returned
        no solution for), ``infeasible_agreed`` (of ``infeasible`` QPs, those it returned
        no solution for), solver-only time if the solver reports it.
    """
    inputs = [general_form(qp) for qp in qps]
    clock = time.perf_counter
    times = np.zeros(len(inputs))
    statuses: Counter[str] = Counter()
    names: set[str] = set()
    solver_times: list[float] = []
    deviations: list[float] = []
    missing = infeasible_agreed = 0
    for i, qp in enumerate(inputs):
        start = clock()
        answer = solver.solve(qp)
        times[i] = clock() - start
        statuses[answer.status] += 1
        names.add(answer.solver)
        if answer.solver_time is not None:
            solver_times.append(answer.solver_time)
        if certified[i]:
            if answer.x is None:
                missing += 1
            else:
                deviations.append(float(np.abs(answer.x - ours[i]).max()))
        elif answer.x is None:
            infeasible_agreed += 1
    comparison = {
        'solver': ', '.join(sorted(names)),
        'statuses': dict(statuses),
        'compared': len(deviations),
        'max_abs_du': max(deviations) if deviations else None,
        'median_abs_du': float(np.median(deviations)) if deviations else None,
        'missing': missing,
        'infeasible': int(np.count_nonzero(~certified)),
        'infeasible_agreed': infeasible_agreed,
        'solver_time_us': statistics(np.array(solver_times)) if solver_times else None,
    }
    return times, comparison


# --------------------------------------------------------------------------------------------
# Figures and report


def statistics(seconds: np.ndarray) -> dict[str, float | int | None]:
    """Median, p99, mean and max of wall times in s, as µs (None when there are none)."""
    if seconds.size == 0:
        return {'n': 0, 'median': None, 'p99': None, 'mean': None, 'max': None}
    us = 1e6 * np.asarray(seconds, dtype=float)
    return {
        'n': int(us.size),
        'median': float(np.median(us)),
        'p99': float(np.percentile(us, 99)),
        'mean': float(us.mean()),
        'max': float(us.max()),
    }


def _counts(values: np.ndarray) -> dict[str, float | int]:
    if values.size == 0:
        return {'median': 0, 'p99': 0, 'max': 0}
    return {
        'median': float(np.median(values)),
        'p99': float(np.percentile(values, 99)),
        'max': int(values.max()),
    }


def machine_info() -> dict[str, Any]:
    """Python and package versions, CPU count and model, load average (1, 5, 15 min)."""
    versions = {}
    for package in VERSIONED_PACKAGES:
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = None
    cpu_model = platform.processor() or platform.machine()
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu_model = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load_average: list[float] | None = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load_average = None
    return {
        'python': platform.python_version(),
        'implementation': platform.python_implementation(),
        'platform': platform.platform(),
        'cpu_count': os.cpu_count(),
        'cpu_model': cpu_model,
        'load_average': load_average,
        'packages': versions,
    }


def _evenly_spaced(n: int, count: int) -> np.ndarray:
    if count <= 0 or n == 0:
        return np.zeros(0, dtype=int)
    return np.unique(np.linspace(0, n - 1, min(count, n)).round().astype(int))


def _parse_override(text: str) -> tuple[str, Any]:
    name, separator, value = text.partition('=')
    if not separator or not name:
        raise argparse.ArgumentTypeError(f'expected NAME=VALUE, got {text!r}')
    lowered = value.strip().lower()
    if lowered in ('true', 'false'):
        return name.strip(), lowered == 'true'
    for kind in (int, float):
        try:
            return name.strip(), kind(value)
        except ValueError:
            pass
    return name.strip(), value


def _ratio(numerator: float | None, denominator: float | None) -> float | None:
    if numerator is None or not denominator:
        return None
    return numerator / denominator


def benchmark(
    config: Path,
    duration: float,
    max_ticks: int | None = None,
    warmup: int = 200,
    external_ticks: int = 1000,
    runner_duration: float = 2.0,
    filter_overrides: dict[str, Any] | None = None,
    log: Callable[[str], None] = lambda message: None,
) -> dict[str, Any]:
    """Run every measurement and return the figures as a JSON-ready document.

    Args:
        config: Scenario parameter file.
        duration: Simulated time of the recorded filtered run (and of the nominal loop), s.
        max_ticks: Replay at most this many ticks (from the start); all if None.
        warmup: Ticks replayed once, untimed, before the measured replay.
        external_ticks: Hard QPs (evenly spaced over the replayed ticks) given to the
            other solvers.
        runner_duration: Simulated time of the runner's run with bag recording, s
            (0: not measured).
        filter_overrides: Safety-filter parameters replaced by dotted name
            (e.g. ``{"osqp.eps_abs": 1e-3}``).
        log: Called with a line saying what is being measured.
    """
    machine = machine_info()
    scenario = Scenario.load(config, filter_overrides)
    log(f'recording the filtered run ({duration:g} s simulated)')
    ticks, filtered_rate, sim_step_times = record_filtered_run(scenario, duration)
    log(f'timing the nominal loop ({duration:g} s simulated)')
    nominal_rate = nominal_loop_rate(scenario, duration)
    replayed = ticks if max_ticks is None else ticks[: max(1, max_ticks)]
    if warmup > 0:
        log(f'warming up on {min(warmup, len(replayed))} ticks')
        replay(scenario, replayed[:warmup])
    qp_ticks = _evenly_spaced(len(replayed), external_ticks)
    log(f'replaying {len(replayed)} ticks')
    measured = replay(scenario, replayed, qp_ticks)

    timings = {key: statistics(measured.times[key]) for key in COMPONENTS}
    ours = measured.u[measured.qp_ticks]
    certified = np.array([measured.status[i] in CERTIFIED for i in measured.qp_ticks], dtype=bool)
    our_step_on_qps = statistics(measured.times['filter_step'][measured.qp_ticks])
    subset_solve_time = measured.filter_qp_solve_time[measured.qp_ticks]
    solved_a_qp = np.array(
        [measured.status[i] is not FilterStatus.NOMINAL for i in measured.qp_ticks], dtype=bool
    )
    our_solve_on_qps = statistics(subset_solve_time[solved_a_qp])
    external: dict[str, Any] = {}
    for solver in external_solvers():
        if solver.solve is None:
            log(f'{solver.label}: skipped, {solver.unavailable}')
            external[solver.key] = {
                'label': solver.label,
                'available': False,
                'reason': solver.unavailable,
            }
            continue
        log(f'{solver.label}: solving {len(measured.qps)} QPs')
        times, comparison = run_external(solver, measured.qps, ours, certified)
        stats = statistics(times)
        external[solver.key] = {
            'label': solver.label,
            'available': True,
            'reason': None,
            'qps': len(measured.qps),
            'time_us': stats,
            'ratio_to_filter_step': {
                'median': _ratio(stats['median'], our_step_on_qps['median']),
                'p99': _ratio(stats['p99'], our_step_on_qps['p99']),
            },
            'ratio_to_filter_qp_solve': {
                'median': _ratio(stats['median'], our_solve_on_qps['median']),
                'p99': _ratio(stats['p99'], our_solve_on_qps['p99']),
            },
            **comparison,
        }

    runner_rate = None
    if runner_duration > 0:
        log(f'timing the runner with bag recording ({runner_duration:g} s simulated)')
        runner_rate = runner_loop_rate(config, runner_duration, scenario.sim_config.time_step)

    statuses = Counter(status.value for status in measured.status)
    status_values = np.array([status.value for status in measured.status])
    step_by_status = {
        status: statistics(measured.times['filter_step'][status_values == status])
        for status in sorted(statuses)
    }
    return {
        'machine': {**machine, 'load_average_after': machine_info()['load_average']},
        'config': str(config),
        'filter_parameters': scenario.filter_config.to_parameters(),
        'run': {
            'duration_requested_s': duration,
            'time_step_s': scenario.sim_config.time_step,
            'integrator': scenario.sim_config.integrator,
            't_end_s': filtered_rate.simulated,
            'ticks': len(ticks),
            'stop_reason': filtered_rate.stop_reason,
            'statuses': dict(Counter(tick.status.value for tick in ticks)),
        },
        'replay': {
            'ticks': len(replayed),
            'warmup_ticks': min(warmup, len(replayed)),
            'statuses': dict(statuses),
            'max_deviation_from_run': measured.max_replay_deviation,
            'osqp_iterations': _counts(measured.osqp_iterations),
            'osqp_statuses': dict(Counter(measured.osqp_status)),
            'filter_osqp_iterations': _counts(measured.filter_iterations),
            'filter_active_set_steps': _counts(measured.active_set_steps),
            'filter_step_us_by_status': step_by_status,
        },
        'timings_us': timings,
        'external': {
            'qps': len(measured.qps),
            'ticks': measured.qp_ticks.tolist(),
            'filter_step_us': our_step_on_qps,
            'filter_qp_solve_us': our_solve_on_qps,
            'solvers': external,
        },
        'real_time_factor': {
            'nominal_loop': nominal_rate.to_json(),
            'filtered_loop': {
                **filtered_rate.to_json(),
                'simulator_step_us': statistics(sim_step_times),
            },
            'runner_with_bag': None if runner_rate is None else runner_rate.to_json(),
        },
    }


def _us(value: float | None) -> str:
    return '-' if value is None else f'{value:,.1f}'


def _times(value: float | None) -> str:
    return '-' if value is None else f'{value:.3g}x'


def format_report(document: dict[str, Any]) -> str:
    """Render the document as a readable table."""
    machine = document['machine']
    packages = ', '.join(f'{k} {v}' for k, v in machine['packages'].items() if v is not None)
    run = document['run']
    replayed = document['replay']
    statuses = ', '.join(f'{k} {v}' for k, v in sorted(replayed['statuses'].items()))
    lines = [
        f'grasp-bench: {document["config"]}',
        f'machine: {machine["implementation"]} {machine["python"]}, {packages}',
        f'         {machine["cpu_count"]} CPUs ({machine["cpu_model"]}), {machine["platform"]}',
        f'         load average (1, 5, 15 min) {machine["load_average"]} before, '
        f'{machine["load_average_after"]} after (other processes add to the p99)',
        '',
        f'filtered run: {run["t_end_s"]:.3f} s of {run["duration_requested_s"]:g} s simulated, '
        f'{run["ticks"]} ticks of {1e3 * run["time_step_s"]:g} ms ({run["integrator"]}), '
        f'stop: {run["stop_reason"]}',
        f'replay: {replayed["ticks"]} ticks after {replayed["warmup_ticks"]} warm-up ticks; '
        f'filter status: {statuses}',
        f'  OSQP iterations (stand-alone) median {replayed["osqp_iterations"]["median"]:g}, '
        f'p99 {replayed["osqp_iterations"]["p99"]:g}, max {replayed["osqp_iterations"]["max"]}; '
        f'active-set steps max {replayed["filter_active_set_steps"]["max"]}',
        '  filter step by status (median / p99 µs): '
        + ', '.join(
            f'{status} {_us(s["median"])} / {_us(s["p99"])}'
            for status, s in replayed['filter_step_us_by_status'].items()
        ),
        '',
        f'{"per tick":42s}{"median µs":>12s}{"p99 µs":>12s}{"max µs":>12s}{"ticks":>8s}',
    ]
    for key, label in COMPONENTS.items():
        s = document['timings_us'][key]
        lines.append(
            f'{label:42s}{_us(s["median"]):>12s}{_us(s["p99"]):>12s}{_us(s["max"]):>12s}'
            f'{s["n"]:>8d}'
        )

    external = document['external']
    step, solve = external['filter_step_us'], external['filter_qp_solve_us']
    lines += [
        '',
        f'same hard QPs, other solvers: {external["qps"]} ticks evenly spaced; on them the filter '
        f'step takes {_us(step["median"])} / {_us(step["p99"])} µs and its QP solve '
        f'{_us(solve["median"])} / {_us(solve["p99"])} µs (median / p99)',
        f'{"solver":38s}{"median µs":>11s}{"p99 µs":>11s}{"/ step":>9s}{"p99/p99":>9s}'
        f'{"/ solve":>9s}{"max |Δu| N·m":>14s}{"compared":>10s}{"infeasible":>12s}',
    ]
    for entry in external['solvers'].values():
        if not entry['available']:
            lines.append(f'{entry["label"]:38s}skipped: {entry["reason"]}')
            continue
        t = entry['time_us']
        to_step, to_solve = entry['ratio_to_filter_step'], entry['ratio_to_filter_qp_solve']
        du = '-' if entry['max_abs_du'] is None else f'{entry["max_abs_du"]:.1e}'
        infeasible = f'{entry["infeasible_agreed"]}/{entry["infeasible"]}'
        lines.append(
            f'{entry["label"] + " [" + entry["solver"] + "]":38s}'
            f'{_us(t["median"]):>11s}{_us(t["p99"]):>11s}{_times(to_step["median"]):>9s}'
            f'{_times(to_step["p99"]):>9s}{_times(to_solve["median"]):>9s}{du:>14s}'
            f'{entry["compared"]:>10d}{infeasible:>12s}'
        )
        if entry['missing']:
            lines.append(f'{"":38s}no solution on {entry["missing"]} feasible QPs')
        not_optimal = {
            k: v for k, v in entry['statuses'].items() if k not in ('optimal', 'solved')
        }
        if not_optimal:
            lines.append(
                f'{"":38s}statuses: ' + ', '.join(f'{k} {v}' for k, v in not_optimal.items())
            )
    lines.append(
        "  (/ step, / solve: median time over the filter step's, its QP solve's; infeasible: "
        'QPs the filter proved infeasible that the solver also returned no solution for)'
    )

    rates = document['real_time_factor']
    lines += [
        '',
        f'{"closed loop":42s}{"simulated s":>12s}{"wall s":>12s}{"real-time factor":>18s}',
    ]
    loops = (
        ('nominal_loop', 'simulator + nominal'),
        ('filtered_loop', 'simulator + nominal + filter'),
        ('runner_with_bag', 'runner, filtered, bag recorded'),
    )
    for key, label in loops:
        rate = rates[key]
        if rate is None:
            lines.append(f'{label:42s}not measured')
            continue
        lines.append(
            f'{label:42s}{rate["simulated_s"]:>12.3f}{rate["wall_s"]:>12.3f}'
            f'{rate["real_time_factor"]:>18.3f}'
        )
    step = rates['filtered_loop']['simulator_step_us']
    lines.append(
        f'  simulator step ({run["integrator"]}): median {_us(step["median"])} µs, '
        f'p99 {_us(step["p99"])} µs'
    )
    return '\n'.join(lines)


def bench_main(argv: list[str] | None = None) -> int:
    """``grasp-bench``: time the model, the QP and the filter over the paper's filtered run."""
    parser = argparse.ArgumentParser(prog='grasp-bench', description=bench_main.__doc__)
    parser.add_argument(
        '--config', type=Path, default=config_path(), help='scenario parameter file'
    )
    parser.add_argument(
        '--duration', type=float, default=15.0, help='simulated time of the runs, s (15)'
    )
    parser.add_argument('--ticks', type=int, help='replay at most N ticks (default: all)')
    parser.add_argument(
        '--warmup', type=int, default=200, help='untimed warm-up ticks before the replay (200)'
    )
    parser.add_argument(
        '--external-ticks',
        type=int,
        default=1000,
        help='hard QPs, evenly spaced, given to cvxpy and daqp (1000; 0: none)',
    )
    parser.add_argument(
        '--runner-duration',
        type=float,
        default=2.0,
        help='simulated time of the runner run with bag recording, s (2; 0: skip)',
    )
    parser.add_argument(
        '--set',
        dest='overrides',
        metavar='NAME=VALUE',
        type=_parse_override,
        action='append',
        default=[],
        help='override a safety-filter parameter, e.g. --set osqp.eps_abs=1e-3',
    )
    parser.add_argument(
        '--soak',
        type=float,
        metavar='SECONDS',
        help='instead: the soak benchmark, a recorded filtered run of SECONDS simulated s '
        '(memory growth, bag size, analysis memory; grasp_safety_filter.soak)',
    )
    parser.add_argument(
        '--soak-interval',
        type=float,
        default=1.0,
        help='simulated s between two memory samples of the soak (1)',
    )
    parser.add_argument(
        '--soak-out',
        type=Path,
        default=Path('soak'),
        help='directory of the soak bags and analyses (replaced; default: soak)',
    )
    parser.add_argument(
        '--json',
        nargs='?',
        const='-',
        metavar='PATH',
        help='print the figures as JSON (the table then goes to stderr), or write them to PATH',
    )
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error(f'--duration: expected > 0 s, got {args.duration}')
    if args.ticks is not None and args.ticks < 1:
        parser.error(f'--ticks: expected >= 1, got {args.ticks}')

    def log(message: str) -> None:
        print(f'grasp-bench: {message}', file=sys.stderr, flush=True)

    from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
    from grasp_safety_filter.model.grasp_check import load_initial_grasp

    try:
        load_initial_grasp(args.config)  # the simulator's start-up checks
    except ConfigError as error:
        print(config_error_line('grasp-bench', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    if args.soak is not None:
        return _soak_main(args, parser, log)
    document = benchmark(
        args.config,
        args.duration,
        max_ticks=args.ticks,
        warmup=max(0, args.warmup),
        external_ticks=max(0, args.external_ticks),
        runner_duration=max(0.0, args.runner_duration),
        filter_overrides=dict(args.overrides),
        log=log,
    )
    _print(format_report(document), document, args.json)
    return 0


def _soak_main(
    args: argparse.Namespace, parser: argparse.ArgumentParser, log: Callable[[str], None]
) -> int:
    """``grasp-bench --soak SECONDS``: see :mod:`grasp_safety_filter.soak`."""
    from grasp_safety_filter.soak import format_soak, soak

    if args.soak <= 0 or args.soak_interval <= 0:
        parser.error('--soak and --soak-interval: expected > 0 s')
    document = soak(
        args.config,
        args.soak,
        args.soak_out,
        interval=args.soak_interval,
        overrides=dict(args.overrides),
        log=log,
    )
    _print(format_soak(document), document, args.json)
    return 0


def _print(report: str, document: dict[str, Any], json_target: str | None) -> None:
    """Print the table; the JSON to stdout (``-``, table to stderr) or to a file."""
    text = json.dumps(document, indent=2) + '\n'
    if json_target == '-':
        print(report, file=sys.stderr)
        sys.stdout.write(text)
    else:
        print(report)
        if json_target is not None:
            Path(json_target).write_text(text)


if __name__ == '__main__':
    sys.exit(bench_main())
