"""``grasp-bench-realtime``: its figures' arithmetic, its driver's schedule, one run over DDS.

The figures and the schedule are checked on synthetic records and recordings, without ROS;
one short run of ``--mode filter`` (200 Hz, 1 s warm-up + 2 s) checks that the filter node's
commands come back stamped exactly as the driver's states and that every figure is reported.
No time is asserted: the timing goals are for the printed figures.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from grasp_tools.bench.real_time import FILTER_CASES, GRAPH_CASES, main, select_cases
from grasp_tools.bench.real_time_driver import driver_plan, STATE, TRACKER
from grasp_tools.bench.real_time_figures import (
    cpu_per_tick,
    figures,
    FilterStatusRecord,
    RunRecords,
)
from grasp_tools.bench.real_time_processes import filter_launch, graph_nodes
from grasp_tools.bench.real_time_recording import Recording

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
MS = 1_000_000
T0 = 1_796_000_000_123_456_789  # a wall-clock stamp of today's epoch, ns

# ----------------------------------------------------------------------------------------
# The figures, from synthetic records: 10 periods of 1 ms, the first 2 ms a warm-up; each
# state relayed in 0.2 ms and answered in 0.5 ms unless a case says otherwise.


def records(**changes) -> RunRecords:
    states = [T0 + k * MS for k in range(10)]
    base = RunRecords(
        period_ns=MS,
        warm_up_ns=2 * MS,
        states=states,
        commands=[(s, s + MS // 2) for s in states],
        relay=[(s, s + MS // 5) for s in states],
        statuses=[],
        driver_lateness=[0] * 10,
    )
    return dataclasses.replace(base, **changes)


def state(k: int) -> int:
    return T0 + k * MS


def answers(latency: dict[int, int] | None = None, missing: tuple[int, ...] = ()) -> list:
    """Commands to each state k not in ``missing``: 0.5 ms after it, or ``latency[k]`` ns."""
    latency = latency or {}
    return [(state(k), state(k) + latency.get(k, MS // 2)) for k in range(10) if k not in missing]


FIGURE_CASES = {
    'every period answered in time': (
        {},
        {'periods': 8, 'computed': 8, 'computed_share': 1.0, 'late_periods': 0},
    ),
    'latencies: the median and p99 of the window, and their ratio to the relay': (
        {},
        {'state_to_command_ms.median': 0.5, 'relay_ms.median': 0.2, 'median_over_relay': 2.5},
    ),
    'a held tick is answered, not computed': (
        {'statuses': [FilterStatusRecord(state(5), 'input_held')]},
        {'answered': 8, 'computed': 7, 'held_or_fallback': 1, 'computed_share': 7 / 8},
    ),
    'grasp and QP fallbacks are not computed either': (
        {
            'statuses': [
                FilterStatusRecord(state(4), 'grasp_held'),
                FilterStatusRecord(state(6), 'fallback_last_good'),
                FilterStatusRecord(state(7), 'relaxed'),
            ]
        },
        {
            'computed': 6,
            'held_or_fallback': 2,
            'statuses': {'grasp_held': 1, 'relaxed': 1, 'fallback_last_good': 1},
        },
    ),
    "a watchdog's status answers no period": (
        {'statuses': [FilterStatusRecord(state(5), 'input_fallback', watchdog=True)]},
        {'computed': 8, 'held_or_fallback': 0},
    ),
    'a period without a command is unanswered': (
        {'commands': answers(missing=(3,))},
        {'answered': 7, 'computed': 7, 'unanswered': 1, 'computed_share': 7 / 8},
    ),
    'a command stamped as no state is another command': (
        {'commands': [*answers(), (state(5) + 1, state(5) + MS)]},
        {'answered': 8, 'other_commands': 1},
    ),
    'a command after the next state + the relay median is late': (
        {'commands': answers({4: MS + MS // 5 + 1})},
        {'late_periods': 1, 'late_share': 1 / 8},
    ),
    'a command at the next state + the relay median exactly is not late': (
        {'commands': answers({4: MS + MS // 5})},
        {'late_periods': 0},
    ),
    'the first receipt of a stamp counts': (
        {'commands': [*answers(), (state(4), state(4) + 9 * MS)]},
        {'late_periods': 0, 'state_to_command_ms.max': 0.5},
    ),
    'the warm-up is left out of every figure': (
        {
            'commands': answers({1: 50 * MS}),
            'statuses': [FilterStatusRecord(state(0), 'input_held', tick_time_us=900.0)],
            'driver_lateness': [MS] * 2 + [0] * 8,
            'relay': [(state(j), state(j) + (9 * MS if j < 2 else MS // 5)) for j in range(10)],
        },
        {
            'periods': 8,
            'computed': 8,
            'late_periods': 0,
            'driver_late_periods': 0,
            'state_to_command_ms.max': 0.5,
            'relay_ms.max': 0.2,
            'filter_tick_ms.count': 0,
        },
    ),
    'driver publications more than half a period late': (
        {'driver_lateness': [0, 0, MS // 2, MS // 2 + 1, 0, 3 * MS, 0, 0, 0, 0]},
        {'driver_late_periods': 2},
    ),
    "the filter's own tick from its statuses in the window": (
        {
            'statuses': [
                FilterStatusRecord(state(k), 'solved', tick_time_us=100.0 * k) for k in (1, 3, 5)
            ]
        },
        {'filter_tick_ms.median': 0.4, 'filter_tick_ms.count': 2},
    ),
    'no relay: no ratio and no late periods': (
        {'relay': []},
        {'median_over_relay': None, 'late_periods': 0, 'relay_ms.count': 0},
    ),
    'a run that starts at its first answer (a plant released by it)': (
        {'start_ns': state(3), 'commands': answers(missing=(0, 1, 2))},
        {'periods': 5, 'computed': 5, 'unanswered': 0},
    ),
    'no driver records in graph mode': (
        {'driver_lateness': None},
        {'driver_late_periods': None},
    ),
}


def lookup(result: dict, dotted: str):
    for part in dotted.split('.'):
        result = result[part]
    return result


@pytest.mark.parametrize('case', list(FIGURE_CASES))
def test_figures_of_synthetic_records(case):
    changes, expected = FIGURE_CASES[case]
    result = figures(records(**changes))
    for key, value in expected.items():
        got = lookup(result, key)
        assert got == (pytest.approx(value) if isinstance(value, float) else value), key


CPU_CASES = {
    # (sample times in ms from T0, CPU s of the process at each, expected ms per period)
    'first and last readings inside the window': ([1, 3, 7, 12], [0.0, 0.01, 0.014, 0.9], 1.0),
    'readings before the warm-up are left out': ([0, 2, 6], [5.0, 0.0, 0.004], 1.0),
    'fewer than two readings inside: none': ([1, 5], [0.0, 0.004], None),
}


@pytest.mark.parametrize('case', list(CPU_CASES))
def test_cpu_per_tick_over_the_periods_between_the_readings(case):
    times, cpu, expected = CPU_CASES[case]
    samples = [(T0 + t * MS, {'filter': c}) for t, c in zip(times, cpu, strict=True)]
    states = [state(k) for k in range(10)]
    result = cpu_per_tick(samples, states, state(2), state(9))
    if expected is None:
        assert result == {}
    else:
        # 3 -> 7 ms: the states of 4, 5, 6 and 7 ms were published in between.
        assert result['filter'] == pytest.approx(expected)
    assert figures(records(cpu_samples=samples))['cpu_ms_per_tick'] == result


def test_no_state_no_figures():
    with pytest.raises(ValueError, match='no state'):
        figures(records(states=[]))


# ----------------------------------------------------------------------------------------
# The driver's schedule and the tracker's noise, on a synthetic recording


def recording(seconds: float = 0.2, seed: int = 1) -> Recording:
    n = round(seconds * 1000)
    rng = np.random.default_rng(seed)
    rotations = np.array([pin.exp3(w) for w in rng.normal(0.0, 0.3, (n, 3))])
    zeros = np.zeros((n, 2))
    return Recording(
        MS, ('j1', 'j2'), 'palm', 'object', zeros, zeros, zeros, zeros,
        rng.normal(0.0, 0.1, (n, 3)), rotations, np.zeros((n, 6)), 'digest',
    )  # fmt: skip


def test_states_every_period_on_the_recordings_steps():
    plan = driver_plan(recording(), 500.0, 0.1, 30.0, 0.033, 0.0)
    assert plan.period_ns == 2 * MS
    assert plan.state_offsets.tolist() == [2 * MS * k for k in range(50)]
    assert plan.state_rows.tolist() == [2 * k for k in range(50)]
    # 333 Hz: a 3 ms period.
    assert driver_plan(recording(), 1000.0 / 3, 0.1, 30.0, 0.0, 0.0).period_ns == 3 * MS


def test_tracker_captures_on_the_recordings_grid_released_after_the_latency():
    rec = recording()
    plan = driver_plan(rec, 500.0, 0.1, 30.0, 0.033, 0.0, 0.0)
    # Captures at 0, 33.3, 66.7 ms on the 1 ms grid; released 33 ms later while the driver
    # runs (its last state at 98 ms): the third would come out at 100 ms.
    assert plan.capture_rows.tolist() == [0, 33]
    assert plan.capture_offsets.tolist() == [0, 33 * MS]
    assert plan.release_offsets.tolist() == [33 * MS, 66 * MS]
    np.testing.assert_array_equal(plan.position, rec.position[[0, 33]])  # no noise
    np.testing.assert_allclose(plan.rotation, rec.rotation[[0, 33]], atol=1e-15)
    events = plan.events()
    assert [e[0] for e in events] == sorted(e[0] for e in events)
    # At 66 ms the state goes out before the tracker's sample.
    at_66 = [(kind, index) for offset, kind, index in events if offset == 66 * MS]
    assert at_66 == [(STATE, 33), (TRACKER, 1)]
    assert len(events) == 50 + 2


def test_a_rate_off_the_recordings_steps_or_too_long_a_run_is_refused():
    with pytest.raises(ValueError, match='whole number'):
        driver_plan(recording(), 400.0, 0.1, 30.0, 0.01, 0.0)
    with pytest.raises(ValueError, match=r'holds 0\.2 s'):
        driver_plan(recording(), 1000.0, 0.5, 30.0, 0.01, 0.0)


def test_tracker_noise_has_the_asked_spread_and_is_seeded():
    rec = recording(seconds=4.0)
    plan = driver_plan(rec, 1000.0, 4.0, 1000.0, 0.0, 0.001, 0.005, seed=3)
    assert len(plan.capture_rows) == 4000
    position_error = plan.position - rec.position[plan.capture_rows]
    assert np.std(position_error, axis=0) == pytest.approx([0.001] * 3, rel=0.06)
    assert np.abs(np.mean(position_error, axis=0)).max() < 1e-4
    tilts = np.array(
        [
            pin.log3(R @ T.T)
            for R, T in zip(plan.rotation, rec.rotation[plan.capture_rows], strict=True)
        ]
    )
    assert np.std(tilts, axis=0) == pytest.approx([0.005] * 3, rel=0.06)
    again = driver_plan(rec, 1000.0, 4.0, 1000.0, 0.0, 0.001, 0.005, seed=3)
    other = driver_plan(rec, 1000.0, 4.0, 1000.0, 0.0, 0.001, 0.005, seed=4)
    np.testing.assert_array_equal(again.position, plan.position)
    assert not np.array_equal(other.position, plan.position)


# ----------------------------------------------------------------------------------------
# What is started


def test_the_cases_and_what_each_mode_starts():
    assert [c.name for c in select_cases('filter', None)] == ['1 kHz', '500 Hz', '333 Hz']
    assert select_cases('graph', '1kHz') == [GRAPH_CASES['1khz']]
    with pytest.raises(ValueError, match='unknown'):
        select_cases('graph', '333hz')
    slow = FILTER_CASES['333hz']
    assert slow.period_ns == 3 * MS
    node = filter_launch(CONFIG, slow)
    command = ' '.join(node.ros_arguments())
    for argument in (
        'input.sync:=latest',
        'use_sim_time:=false',
        'object_state.correction_time:=0.5',
    ):
        assert argument in command
    nodes = {n.name: n for n in graph_nodes(CONFIG, GRAPH_CASES['500hz'], 11.0, 'mujoco')}
    assert set(nodes) == {'hand_sim_node', 'nominal_controller_node', 'safety_filter_node'}
    simulator = nodes['hand_sim_node'].overrides
    assert simulator['lockstep'] is False
    assert simulator['hardware.rate'] == 500.0
    assert simulator['tracker.rate'] == 100.0
    assert simulator['tracker.latency'] == 0.01
    assert simulator['tracker.position_noise'] == 0.0005
    assert simulator['duration'] == 11.0
    assert simulator['plant'] == 'mujoco'
    assert simulator['mujoco.cone'] == 'elliptic'
    assert simulator['mujoco.noslip_iterations'] == 10


# ----------------------------------------------------------------------------------------
# One short run over DDS

REPORTED = {
    'periods', 'periods_published', 'warm_up_s', 'window_s', 'period_ms', 'answered',
    'computed', 'computed_share', 'held_or_fallback', 'unanswered', 'other_commands',
    'statuses', 'state_to_command_ms', 'relay_ms', 'median_over_relay', 'p99_over_relay',
    'late_periods', 'late_share', 'driver_late_periods', 'filter_tick_ms', 'cpu_ms_per_tick',
    'case', 'load_average_before', 'load_average_after',
}  # fmt: skip


def test_filter_mode_over_dds_answers_the_drivers_states(tmp_path, capsys):
    out = tmp_path / 'figures.json'
    work = tmp_path / 'work'
    arguments = [
        '--rate', '200', '--duration', '2', '--warm-up', '1', '--json', str(out),
        '--recording', str(tmp_path / 'recording.npz'), '--work-dir', str(work),
        '--domain-id', os.environ['ROS_DOMAIN_ID'],
    ]  # fmt: skip
    assert main(arguments) == 0
    printed = capsys.readouterr().out
    result = json.loads(out.read_text(encoding='utf-8'))['cases']['200 Hz']
    assert set(result) == REPORTED
    assert result['periods_published'] == 600
    assert set(result['cpu_ms_per_tick']) == {'monitor', 'relay', 'safety_filter_node', 'driver'}
    for label in (
        'answered by a computed u*',
        'state -> command latency',
        'relay (bare rclpy',
        'filter / relay',
        'late periods',
        'driver publications',
        'CPU per period',
    ):
        assert label in printed, label
    # Every command is stamped exactly as one of the driver's states (integer ns), but for
    # the input watchdog's (stamped with the filter's clock once the driver has stopped).
    (run,) = work.iterdir()
    driver = json.loads((run / 'driver.json').read_text(encoding='utf-8'))
    monitor = json.loads((run / 'monitor.json').read_text(encoding='utf-8'))
    states = set(driver['stamps'])
    watchdog = {stamp for stamp, _, is_watchdog, _ in monitor['statuses'] if is_watchdog}
    commands = {stamp for stamp, _ in monitor['received']['/hand/effort_command']}
    assert commands & states
    assert commands - states <= watchdog
    measured = {stamp for stamp in states if stamp >= driver['stamps'][0] + 1_000_000_000}
    assert result['answered'] == len(commands & measured)
