"""Replay of recorded ticks: the filter's pieces timed one by one on the same inputs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import time
from typing import NamedTuple

import numpy as np
import osqp

from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.control.qp_solvers import osqp_backend
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
)
from grasp_safety_filter.model.grasp_model import state_of
from grasp_tools.bench.recorded_run import Scenario, Tick

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

#: Pieces of a tick also timed in thread CPU time: the filter node's own work.
CPU_COMPONENTS: tuple[str, ...] = ('model_state', 'filter_step', 'node_tick')

#: Statuses whose u* solves the hard QP (the others are answers to an infeasible one).
CERTIFIED = frozenset((FilterStatus.NOMINAL, FilterStatus.SOLVED))


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
        cpu_times: Thread CPU time per tick of the node tick's pieces (the keys of
            :data:`CPU_COMPONENTS`), s: what the tick itself costs, without the time the
            thread waited for a CPU (this machine is shared; wall p99 measures the scheduler).
        u: The filter's u* per tick, shape (ticks, m).
        status: The filter's status per tick.
        osqp_iterations: Iterations of the stand-alone OSQP solve per tick.
        osqp_status: Its status per tick.
        filter_iterations: The QP solvers' iterations inside the filter per tick (0 when
            none ran).
        filter_qp_solve_time: The filter's own solve time per tick (``FilterResult.solve_time``:
            hard and relaxed QP; 0 on ``nominal`` ticks), s.
        qps: The hard QP of the ticks in ``qp_ticks``.
        qp_ticks: Indices (into the replayed ticks) of :attr:`qps`.
        max_replay_deviation: ``max |u*_replay - u*_recorded|``, N·m (0 when the replay
            reproduces the run).
    """

    times: dict[str, np.ndarray]
    cpu_times: dict[str, np.ndarray]
    u: np.ndarray
    status: list[FilterStatus]
    osqp_iterations: np.ndarray
    osqp_status: list[str]
    filter_iterations: np.ndarray
    filter_qp_solve_time: np.ndarray
    qps: list[DenseQP]
    qp_ticks: np.ndarray
    max_replay_deviation: float


def _standalone_osqp(safety_filter: SafetyFilter) -> osqp.OSQP:
    """Set up an OSQP solver like the filter's hard-QP solver (same pattern and settings)."""
    hard = safety_filter.hard_qp
    solver = osqp.OSQP()
    settings = {**osqp_backend.DEFAULT_SETTINGS, **safety_filter.config.osqp_settings()}
    solver.setup(hard.P, hard.q, hard.C, hard.lower, hard.upper, **settings)
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
    clock, cpu_clock = time.perf_counter, time.thread_time
    n = len(ticks)
    times = {key: np.zeros(n) for key in COMPONENTS if key != 'filter_qp_solve'}
    cpu_times = {key: np.zeros(n) for key in CPU_COMPONENTS}
    qp_solve_times = np.zeros(n)
    u = np.zeros((n, model.n_joints))
    status: list[FilterStatus] = []
    osqp_iterations = np.zeros(n, dtype=int)
    osqp_status: list[str] = []
    filter_iterations = np.zeros(n, dtype=int)
    qps: list[DenseQP] = []
    kept: list[int] = []
    for i, tick in enumerate(ticks):
        # The node's tick: model terms then the filter step, back to back. The CPU clock
        # (~2 us a read here) is read outside the wall-clock interval it brackets.
        c0 = cpu_clock()
        t0 = clock()
        state = state_of(model, tick)
        t1 = clock()
        c1 = cpu_clock()
        result = safety_filter.solve(state, tick.u_nom)
        t2 = clock()
        c2 = cpu_clock()
        times['model_state'][i] = t1 - t0
        times['filter_step'][i] = t2 - t1
        times['node_tick'][i] = t2 - t0
        cpu_times['model_state'][i] = c1 - c0
        cpu_times['filter_step'][i] = c2 - c1
        cpu_times['node_tick'][i] = c2 - c0
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
        if i in wanted:
            qps.append(DenseQP(*hard.dense()))
            kept.append(i)
    solved_a_qp = np.array([s is not FilterStatus.NOMINAL for s in status], dtype=bool)
    times['filter_qp_solve'] = qp_solve_times[solved_a_qp]
    recorded = np.array([tick.u for tick in ticks]).reshape(n, model.n_joints)
    return Replay(
        times={key: times[key] for key in COMPONENTS},
        cpu_times=cpu_times,
        u=u,
        status=status,
        osqp_iterations=osqp_iterations,
        osqp_status=osqp_status,
        filter_iterations=filter_iterations,
        filter_qp_solve_time=qp_solve_times,
        qps=qps,
        qp_ticks=np.array(kept, dtype=int),
        max_replay_deviation=float(np.abs(u - recorded).max(initial=0.0)),
    )


def statistics(seconds: np.ndarray) -> dict[str, float | int | None]:
    """Median, p99, mean and max of times in s, as µs (None when there are none)."""
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
