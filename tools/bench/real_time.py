"""``grasp-bench-realtime``: the safety filter in real time over DDS, as on a real hand.

Each case is a run of its own, of OS processes on a ROS domain of its own
(:mod:`.real_time_processes`):

- ``--mode filter``: ``safety_filter_node`` alone (``input.sync: latest``, wall clock), as
  on a hand whose driver is not Python. A lean driver (:mod:`.real_time_driver`) replays the
  paper's recorded filtered run at the case's rate, publishing each state and the u_nom
  stamped as it, and a tracker's delayed, noisy poses.
- ``--mode graph``: ``hand_sim_node`` in its hardware mode, ``nominal_controller_node`` and
  ``safety_filter_node``, as ``real_hand(config, simulate=True)`` starts them, with the
  case's rate and tracker given to the simulator (``--plant mujoco``: MuJoCo with elliptic
  cones and the no-slip solver).

In both, a relay republishes each joint state (a bare rclpy hop: the baseline) and a monitor
notes when commands, relayed states and statuses arrive (:mod:`.real_time_nodes`). Printed
per case (:mod:`.real_time_figures`), after a warm-up: the share of control periods
answered by a computed u*, the state -> command latency next to the relay's, late periods,
and each process's CPU time per period. Nothing here asserts a time: the figures are for
reading (``--json PATH`` writes them too).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import sys
import tempfile
from typing import Any

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import load_node_parameters, SAFETY_FILTER_NODE
from grasp_safety_filter.io.sim_diagnostic_keys import SimKey
from grasp_tools.bench.real_time_driver import ORIENTATION_NOISE
from grasp_tools.bench.real_time_figures import figures
from grasp_tools.bench.real_time_processes import (
    bench_environment,
    Case,
    run_filter_case,
    run_graph_case,
)
from grasp_tools.bench.real_time_recording import load_or_record

PROGRAM = 'grasp-bench-realtime'

#: A driver and tracker of a torque-controlled hand: 100 Hz tracker, 10 ms late, 0.5 mm.
_TRACKER_100 = {'tracker_rate': 100.0, 'latency': 0.010, 'noise': 0.0005}

#: ``--mode filter`` cases, by ``--cases`` name.
FILTER_CASES = {
    '1khz': Case('1 kHz', 0.001, **_TRACKER_100),
    '500hz': Case('500 Hz', 0.002, **_TRACKER_100),
    # An Allegro-like 333 Hz driver with a 30 Hz camera: a longer correction for its noise.
    '333hz': Case('333 Hz', 0.003, 30.0, 0.033, 0.001, correction_time=0.5),
}

#: ``--mode graph`` cases, by ``--cases`` name.
GRAPH_CASES = {
    '500hz': Case('500 Hz', 0.002, **_TRACKER_100),
    '1khz': Case('1 kHz', 0.001, **_TRACKER_100),
}

CASES = {'filter': FILTER_CASES, 'graph': GRAPH_CASES}

#: The simulator's hardware-mode counts reported with a graph run (its ``hand_sim`` values).
SIMULATOR_COUNTS = (
    'periods.published',
    'periods.late',
    'periods.skipped',
    'commands.received',
    'command.timeouts',
    'tracker.samples',
)

#: Extra recording beyond the driver's run, s (none is needed; a margin against rounding).
RECORDING_MARGIN = 0.1


def select_cases(mode: str, names: str | None, custom: Case | None = None) -> list[Case]:
    """Return the cases to run: ``custom`` if given, else ``names`` (comma-separated) or all.

    Raises:
        ValueError: An unknown case name.
    """
    if custom is not None:
        return [custom]
    table = CASES[mode]
    if not names:
        return list(table.values())
    chosen = [name.strip().lower().replace(' ', '') for name in names.split(',') if name.strip()]
    unknown = [name for name in chosen if name not in table]
    if unknown:
        raise ValueError(f'--cases: unknown {unknown} for --mode {mode}; known: {list(table)}')
    return [table[name] for name in chosen]


def default_domain() -> int:
    """Return a ROS domain of this run's own (201-230, by process id)."""
    return 201 + os.getpid() % 30


def outcome_text(outcome: dict[str, Any]) -> str:
    """Return how the simulator's run ended, in words."""
    final = outcome.get('final') or {}
    reason = final.get(SimKey.RUN_STOP_REASON)
    if reason == 'duration':
        return 'ran the whole duration'
    if reason:
        return f'stopped: {reason} at t = {final.get(SimKey.RUN_T_END, "?")} s'
    return f'no end-of-run status (hand_sim_node exit code {outcome.get("exit_code")})'


def run_case(
    args: argparse.Namespace, case: Case, recording: Any, directory: Path, env: dict[str, str]
) -> dict[str, Any]:
    """Run one case in ``directory``; return its figures, the case and the machine's load."""
    load = [round(x, 2) for x in os.getloadavg()]
    extra: dict[str, Any] = {}
    if args.mode == 'filter':
        records = run_filter_case(
            case, args.config, recording, args.duration, args.warm_up, directory, env,
            args.object_message,
        )  # fmt: skip
    else:
        records, outcome = run_graph_case(
            case, args.config, args.duration, args.warm_up, directory, env, args.plant
        )
        values = outcome['final'] or outcome['last_status']
        extra = {
            'outcome': outcome_text(outcome),
            'simulator': {key: values.get(key) for key in SIMULATOR_COUNTS},
        }
    result = figures(records)
    result.update(extra)
    result['case'] = {'name': case.name, 'description': case.describe()}
    result['load_average_before'] = load
    result['load_average_after'] = [round(x, 2) for x in os.getloadavg()]
    return result


def _stats(label: str, stats: dict[str, Any], unit: str = 'ms') -> str:
    if stats['median'] is None:
        return f'  {label:<40} (none)'
    return (
        f'  {label:<40} median {stats["median"]:7.3f}  p99 {stats["p99"]:7.3f} {unit}'
        f'  ({stats["count"]})'
    )


def _percent(share: float | None) -> str:
    return 'n/a' if share is None else f'{100.0 * share:.2f} %'


def format_case(result: dict[str, Any]) -> str:
    """Return one case's figures as text."""
    ratio = result['median_over_relay']
    ratio_p99 = result['p99_over_relay']
    statuses = ', '.join(f'{k or "?"} {v}' for k, v in sorted(result['statuses'].items()))
    lines = [
        f'case {result["case"]["description"]}',
        f'  load average before/after: {result["load_average_before"]} / '
        f'{result["load_average_after"]}',
        f'  periods measured: {result["periods"]} of {result["periods_published"]} published '
        f'({result["warm_up_s"]:g} s warm-up left out)',
        f'  answered by a computed u*: {_percent(result["computed_share"])} '
        f'({result["computed"]}; held or fallback {result["held_or_fallback"]}, '
        f'unanswered {result["unanswered"]}, other commands {result["other_commands"]})',
        f'  statuses published (non-steady at once, steady at diagnostics.period): '
        f'{statuses or "none"}',
        _stats('state -> command latency', result['state_to_command_ms']),
        _stats('relay (bare rclpy hop) latency', result['relay_ms']),
        '  filter / relay: '
        + ('n/a' if ratio is None else f'median {ratio:.2f} x')
        + ('' if ratio_p99 is None else f', p99 {ratio_p99:.2f} x'),
        _stats("filter's own tick (tick_time_us)", result['filter_tick_ms']),
        f'  late periods (command after the next state + relay median): '
        f'{result["late_periods"]} ({_percent(result["late_share"])})',
    ]
    if result['driver_late_periods'] is not None:
        lines.append(
            f'  driver publications more than half a period late: {result["driver_late_periods"]}'
        )
    cpu = result['cpu_ms_per_tick']
    lines.append(
        '  CPU per period: '
        + (', '.join(f'{name} {ms:.3f} ms' for name, ms in cpu.items()) or '(no readings)')
    )
    if 'outcome' in result:
        counts = ', '.join(f'{k} {v}' for k, v in result['simulator'].items() if v is not None)
        lines.append(f'  simulator: {result["outcome"]}' + (f' ({counts})' if counts else ''))
    return '\n'.join(lines)


def heading(results: dict[str, Any]) -> str:
    """Return the report's first line: the mode, the run lengths and the machine."""
    return (
        f'{PROGRAM} --mode {results["mode"]}: {results["duration_s"]:g} s per case after a '
        f'{results["warm_up_s"]:g} s warm-up; ROS_DOMAIN_ID {results["ros_domain_id"]}; '
        f'{results["machine"]["cpu_count"]} CPUs ({results["machine"]["cpu_model"]})'
    )


def report(results: dict[str, Any]) -> str:
    """Return every case's figures as text (rebuilt from the JSON alone)."""
    return '\n'.join([heading(results), *(format_case(r) for r in results['cases'].values())])


def parser() -> argparse.ArgumentParser:
    """Return the command line's parser."""
    p = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.splitlines()[0])
    p.add_argument('--mode', choices=('filter', 'graph'), default='filter')
    p.add_argument(
        '--cases',
        help=f'comma-separated (filter: {",".join(FILTER_CASES)}; '
        f'graph: {",".join(GRAPH_CASES)}; default: all of the mode)',
    )
    p.add_argument('--duration', type=float, default=10.0, help='measured s per case (10)')
    p.add_argument('--warm-up', type=float, default=1.0, help='s left out first (1)')
    p.add_argument('--config', type=Path, default=config_path(), help='scenario file')
    p.add_argument('--rate', type=float, help='instead of --cases: one case at this rate, Hz')
    p.add_argument('--tracker-rate', type=float, default=100.0, help='with --rate, Hz (100)')
    p.add_argument('--latency', type=float, default=0.010, help='with --rate: tracker, s')
    p.add_argument('--noise', type=float, default=0.0005, help='with --rate: tracker, m')
    p.add_argument('--correction-time', type=float, help="with --rate, s (the file's)")
    p.add_argument(
        '--object-message',
        choices=('odometry', 'pose'),
        default='odometry',
        help='filter mode: the tracker publishes /object/odom or /object/pose',
    )
    p.add_argument('--plant', choices=('rigid', 'mujoco'), default='rigid', help='graph mode')
    p.add_argument(
        '--recording',
        type=Path,
        help='filter mode: the recorded run (.npz), '
        'reused if it fits this config and is long enough, else written',
    )
    p.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID of the runs (201-230)')
    p.add_argument('--work-dir', type=Path, help='keep the logs and records here')
    p.add_argument('--json', type=Path, help='also write the figures to this file')
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``grasp-bench-realtime`` (module docstring)."""
    args = parser().parse_args(argv)
    custom = None
    if args.rate is not None:
        custom = Case(
            f'{args.rate:g} Hz', 1.0 / args.rate, args.tracker_rate, args.latency, args.noise,
            ORIENTATION_NOISE, args.correction_time,
        )  # fmt: skip
    try:
        cases = select_cases(args.mode, args.cases, custom)
        load_node_parameters(args.config, SAFETY_FILTER_NODE)
    except ValueError as error:
        print(f'{PROGRAM}: {error}', file=sys.stderr)
        return 2
    except ConfigError as error:
        print(config_error_line(PROGRAM, error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    from grasp_tools.bench.machine import machine_info

    domain = default_domain() if args.domain_id is None else args.domain_id
    env = bench_environment(domain)
    recording = None
    if args.mode == 'filter':  # before any timed run
        length = args.warm_up + args.duration + RECORDING_MARGIN
        recording = load_or_record(args.config, length, args.recording)
    results: dict[str, Any] = {
        'mode': args.mode,
        'duration_s': args.duration,
        'warm_up_s': args.warm_up,
        'ros_domain_id': domain,
        'machine': machine_info(),
        'cases': {},
    }
    print(heading(results), flush=True)
    with tempfile.TemporaryDirectory(prefix='grasp-bench-realtime-') as tmp:
        root = Path(tmp) if args.work_dir is None else args.work_dir
        for index, case in enumerate(cases):
            directory = root / f'{index}_{case.name.replace(" ", "")}'
            directory.mkdir(parents=True, exist_ok=True)
            try:
                results['cases'][case.name] = run_case(args, case, recording, directory, env)
            except (RuntimeError, ValueError) as error:
                print(f'{PROGRAM}: case {case.name}: {error}', file=sys.stderr)
                return 1
            print(format_case(results['cases'][case.name]), flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2), encoding='utf-8')
    return 0


if __name__ == '__main__':
    sys.exit(main())
