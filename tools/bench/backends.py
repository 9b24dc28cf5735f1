"""The same replayed ticks through every QP backend (``qp.solver``), side by side.

Each backend gets its own filter (its own warm starts), and every tick is given to all of
them in turn, the order rotating from tick to tick, so that each sees the same machine
load: the comparison is made in one run, not across runs. Per backend the node tick
(model terms + filter step) is timed in thread CPU time and wall time, its QP solve is the
filter's own ``solve_time`` (wall), and its u* is compared with the first backend's.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
import dataclasses
from dataclasses import dataclass
import time
from typing import Any

import numpy as np

from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.control.safety_filter import FilterStatus, SafetyFilter
from grasp_safety_filter.model.grasp_model import state_of
from grasp_tools.bench.recorded_run import Scenario, Tick
from grasp_tools.bench.replay import CERTIFIED, statistics


@dataclass(frozen=True, eq=False)
class BackendReplay:
    """One backend's node ticks on the replayed ticks.

    Attributes:
        backend: The ``qp.solver`` value.
        cpu: Thread CPU time of each node tick, s, shape (ticks,).
        wall: Wall time of each node tick, s, shape (ticks,).
        solve: The filter's QP solve per tick (``FilterResult.solve_time``, wall; 0 on a
            tick that solved no QP), s, shape (ticks,).
        u: u* per tick, shape (ticks, m), N·m.
        status: The filter's status per tick.
    """

    backend: str
    cpu: np.ndarray
    wall: np.ndarray
    solve: np.ndarray
    u: np.ndarray
    status: list[FilterStatus]


def replay_backends(
    scenario: Scenario, ticks: Sequence[Tick], backends: Sequence[str]
) -> list[BackendReplay]:
    """Replay ``ticks`` through one filter per backend, interleaved tick by tick.

    Raises:
        ValueError: No ticks, or a backend that :data:`BACKENDS` does not know.
    """
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown or not backends:
        raise ValueError(
            f'backends: expected one or more of {", ".join(BACKENDS)}, got {list(backends)!r}'
        )
    if not ticks:
        raise ValueError('replay_backends: expected at least one tick, got none')
    model = scenario.model
    filters: list[SafetyFilter] = [
        SafetyFilter.from_config(model, dataclasses.replace(scenario.filter_config, solver=b))
        for b in backends
    ]
    n, k = len(ticks), len(backends)
    cpu, wall, solve = np.zeros((k, n)), np.zeros((k, n)), np.zeros((k, n))
    u = np.zeros((k, n, model.n_joints))
    status: list[list[FilterStatus]] = [[] for _ in backends]
    clock, cpu_clock = time.perf_counter, time.thread_time
    for i, tick in enumerate(ticks):
        for j in np.roll(np.arange(k), -(i % k)):
            c0 = cpu_clock()
            t0 = clock()
            state = state_of(model, tick)
            result = filters[j].solve(state, tick.u_nom)
            t1 = clock()
            c1 = cpu_clock()
            cpu[j, i], wall[j, i] = c1 - c0, t1 - t0
            solve[j, i] = result.solve_time
            u[j, i] = result.u
            status[j].append(result.status)
    return [
        BackendReplay(
            backend=b, cpu=cpu[j], wall=wall[j], solve=solve[j], u=u[j], status=status[j]
        )
        for j, b in enumerate(backends)
    ]


def backend_table(replays: Sequence[BackendReplay]) -> dict[str, Any]:
    """JSON-ready figures per backend: node tick CPU and wall time, statuses, agreement.

    ``qp_solve_wall_us``: the filter's QP solve on the ticks that solved one (wall time: the
    filter times its solve so); ``node_tick_over_qp_solve``: on those ticks, the node tick's
    median wall time over the solve's (None if no tick solved a QP).
    ``max_abs_du_vs_first``: the largest ``|u* - u*_first|`` (N·m) over the ticks that both
    this backend and the first one certified as optimal for the hard QP.
    """
    first = replays[0]
    first_certified = np.array([s in CERTIFIED for s in first.status], dtype=bool)
    table: dict[str, Any] = {}
    for replay in replays:
        certified = first_certified & np.array([s in CERTIFIED for s in replay.status])
        du = np.abs(replay.u[certified] - first.u[certified])
        statuses = np.array([s.value for s in replay.status])
        solved_a_qp = replay.solve > 0.0
        ratio = (
            float(np.median(replay.wall[solved_a_qp]) / np.median(replay.solve[solved_a_qp]))
            if solved_a_qp.any()
            else None
        )
        table[replay.backend] = {
            'node_tick_cpu_us': statistics(replay.cpu),
            'node_tick_wall_us': statistics(replay.wall),
            'node_tick_cpu_us_by_status': {
                value: statistics(replay.cpu[statuses == value]) for value in sorted(set(statuses))
            },
            'qp_solve_wall_us': statistics(replay.solve[solved_a_qp]),
            'node_tick_over_qp_solve': ratio,
            'statuses': dict(Counter(statuses.tolist())),
            'max_abs_du_vs_first': float(du.max(initial=0.0)),
            'compared_ticks': int(certified.sum()),
        }
    return table
