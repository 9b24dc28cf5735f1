"""The benchmark document and its printed table."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.control.safety_filter import FilterStatus
from grasp_tools.bench.backends import backend_table, replay_backends
from grasp_tools.bench.external_solvers import external_solvers, run_external
from grasp_tools.bench.hands import compare_hands, format_hands
from grasp_tools.bench.machine import machine_info, noise_floor
from grasp_tools.bench.node_callbacks import FilterCallbackTimes
from grasp_tools.bench.recorded_run import (
    nominal_loop_rate,
    record_filtered_run,
    runner_loop_rate,
    Scenario,
)
from grasp_tools.bench.replay import (
    CERTIFIED,
    COMPONENTS,
    CPU_COMPONENTS,
    replay,
    statistics,
)

#: The per-tick table's row of the runner's filter-node callbacks.
CALLBACKS_LABEL = 'filter node callbacks (parse, model, filter step, messages)'


def _counts(values: np.ndarray) -> dict[str, float | int]:
    if values.size == 0:
        return {'median': 0, 'p99': 0, 'max': 0}
    return {
        'median': float(np.median(values)),
        'p99': float(np.percentile(values, 99)),
        'max': int(values.max()),
    }


def _evenly_spaced(n: int, count: int) -> np.ndarray:
    if count <= 0 or n == 0:
        return np.zeros(0, dtype=int)
    return np.unique(np.linspace(0, n - 1, min(count, n)).round().astype(int))


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
    backends: Sequence[str] = tuple(BACKENDS),
    model_overrides: dict[str, Any] | None = None,
    log: Callable[[str], None] = lambda message: None,
    compare_configs: Sequence[Path] = (),
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
        backends: QP backends (``qp.solver`` values) to compare on the replayed ticks
            (:mod:`grasp_tools.bench.backends`); none: not compared.
        model_overrides: ``model.*`` parameters replaced by dotted name, for every part
            (e.g. ``{"model.torsional_friction": 0.005}``: soft fingers).
        log: Called with a line saying what is being measured.
        compare_configs: Other scenarios whose hands' node ticks are compared with this
            one's in the same run (:mod:`grasp_tools.bench.hands`; the same
            overrides apply); none: not compared.
    """
    machine = machine_info()
    scenario = Scenario.load(config, filter_overrides, model_overrides)
    log(f'recording the filtered run ({duration:g} s simulated)')
    ticks, filtered_rate, sim_step_times, sim_step_cpu_times = record_filtered_run(
        scenario, duration
    )
    log(f'timing the nominal loop ({duration:g} s simulated)')
    nominal_rate = nominal_loop_rate(scenario, duration)
    replayed = ticks if max_ticks is None else ticks[: max(1, max_ticks)]
    if warmup > 0:
        log(f'warming up on {min(warmup, len(replayed))} ticks')
        replay(scenario, replayed[:warmup])
    qp_ticks = _evenly_spaced(len(replayed), external_ticks)
    log(f'timing the same compiled work {len(replayed)} times (the noise floor)')
    floor = noise_floor(len(replayed))
    log(f'replaying {len(replayed)} ticks')
    measured = replay(scenario, replayed, qp_ticks)

    timings = {key: statistics(measured.times[key]) for key in COMPONENTS}
    cpu_timings = {key: statistics(measured.cpu_times[key]) for key in CPU_COMPONENTS}
    backend_figures = None
    if backends:
        log(f'replaying {len(replayed)} ticks through {", ".join(backends)}, interleaved')
        backend_figures = backend_table(replay_backends(scenario, replayed, backends))
    hand_figures = compare_hands(
        (str(config), scenario, replayed), compare_configs, duration, warmup, log,
        (filter_overrides, model_overrides),
    ) if compare_configs else None
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
    callback_times = FilterCallbackTimes()
    if runner_duration > 0:
        log(f'timing the runner with bag recording ({runner_duration:g} s simulated)')
        runner_rate = runner_loop_rate(
            config,
            runner_duration,
            scenario.sim_config.time_step,
            {**(filter_overrides or {}), **(model_overrides or {})},
            callback_times,
        )

    statuses = Counter(status.value for status in measured.status)
    status_values = np.array([status.value for status in measured.status])
    step_by_status = {
        status: statistics(measured.times['filter_step'][status_values == status])
        for status in sorted(statuses)
    }
    node_tick_cpu_by_status = {
        status: statistics(measured.cpu_times['node_tick'][status_values == status])
        for status in sorted(statuses)
    }
    return {
        'machine': {**machine, 'load_average_after': machine_info()['load_average']},
        'config': str(config),
        'filter_parameters': scenario.filter_config.to_parameters(),
        'model_overrides': dict(model_overrides or {}),
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
            'filter_step_us_by_status': step_by_status,
            'node_tick_cpu_us_by_status': node_tick_cpu_by_status,
        },
        'timings_us': timings,
        'cpu_timings_us': cpu_timings,
        # The runner's lockstep run (None: not run): the endpoint's three callbacks a tick.
        'filter_node_callbacks_cpu_us': (
            None if runner_rate is None else statistics(callback_times.per_tick())
        ),
        'noise_floor': floor,
        'backends': backend_figures,
        'hands': hand_figures,
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
                'simulator_step_cpu_us': statistics(sim_step_cpu_times),
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
    width = max(42, len(CALLBACKS_LABEL) + 2)  # the per-tick table's label column
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
        f'p99 {replayed["osqp_iterations"]["p99"]:g}, max {replayed["osqp_iterations"]["max"]}',
        '  filter step by status (wall, median / p99 µs): '
        + ', '.join(
            f'{status} {_us(s["median"])} / {_us(s["p99"])}'
            for status, s in replayed['filter_step_us_by_status'].items()
        ),
        '  node tick by status (thread CPU, median / p99 µs): '
        + ', '.join(
            f'{status} {_us(s["median"])} / {_us(s["p99"])}'
            for status, s in replayed['node_tick_cpu_us_by_status'].items()
        ),
        '',
        f'{"per tick":{width}s}{"wall median":>12s}{"p99":>9s}{"max":>9s}'
        f'{"CPU median":>12s}{"p99":>9s}{"ticks":>8s}   (µs)',
    ]
    for key, label in COMPONENTS.items():
        s = document['timings_us'][key]
        cpu = document['cpu_timings_us'].get(key)
        cpu_columns = (
            f'{_us(cpu["median"]):>12s}{_us(cpu["p99"]):>9s}' if cpu else f'{"-":>12s}{"-":>9s}'
        )
        lines.append(
            f'{label:{width}s}{_us(s["median"]):>12s}{_us(s["p99"]):>9s}{_us(s["max"]):>9s}'
            f'{cpu_columns}{s["n"]:>8d}'
        )
    callbacks = document['filter_node_callbacks_cpu_us']
    if callbacks is None:
        lines.append(f'{CALLBACKS_LABEL:{width}s}not measured (runner not run)')
    else:
        lines.append(
            f'{CALLBACKS_LABEL:{width}s}{"-":>12s}{"-":>9s}{"-":>9s}'
            f'{_us(callbacks["median"]):>12s}{_us(callbacks["p99"]):>9s}{callbacks["n"]:>8d}'
            '   (runner, lockstep)'
        )
    floor = document['noise_floor']
    lines.append(
        "  noise floor (the same compiled work every call: the spread is the machine's): "
        f'CPU median {_us(floor["cpu_us"]["median"])} µs, p99 {_us(floor["cpu_us"]["p99"])} '
        f'µs, p99/median {floor["p99_over_median"]:.2f}'
    )
    if document['backends']:
        lines += [
            '',
            'QP backends (qp.solver) on the same ticks, interleaved; node tick in µs:',
            f'{"backend":12s}{"CPU median":>12s}{"p99":>9s}{"wall median":>13s}{"p99":>9s}'
            f'{"QP solve":>10s}{"p99":>9s}{"tick/QP":>9s}'
            f'{"max |Δu*| N·m":>15s}{"compared":>10s}   statuses',
        ]
        for backend, entry in document['backends'].items():
            cpu, wall = entry['node_tick_cpu_us'], entry['node_tick_wall_us']
            solve, ratio = entry['qp_solve_wall_us'], entry['node_tick_over_qp_solve']
            counts = ', '.join(f'{k} {v}' for k, v in sorted(entry['statuses'].items()))
            lines.append(
                f'{backend:12s}{_us(cpu["median"]):>12s}{_us(cpu["p99"]):>9s}'
                f'{_us(wall["median"]):>13s}{_us(wall["p99"]):>9s}'
                f'{_us(solve["median"]):>10s}{_us(solve["p99"]):>9s}'
                f'{_times(ratio):>9s}'
                f'{entry["max_abs_du_vs_first"]:>15.1e}{entry["compared_ticks"]:>10d}   {counts}'
            )
        lines += [
            "  (QP solve: the filter's solve_time, wall, on the ticks that solved a QP; tick/QP:"
            " their node tick's",
            '   median wall time over it; max |Δu*|: against the first backend, on ticks both'
            ' certified optimal)',
        ]

    if document.get('hands'):
        lines += format_hands(document['hands'])

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
    cpu = rates['filtered_loop']['simulator_step_cpu_us']
    lines.append(
        f'  simulator step ({run["integrator"]}): CPU median {_us(cpu["median"])} µs, '
        f'p99 {_us(cpu["p99"])} µs; wall median {_us(step["median"])} µs, '
        f'p99 {_us(step["p99"])} µs'
    )
    return '\n'.join(lines)
