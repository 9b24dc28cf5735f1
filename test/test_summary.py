"""The analysis reads what the filter writes: statuses counted, a late recording reported."""

from __future__ import annotations

from collections import Counter, deque
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.filter_statuses import FilterStatusReader
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.cli import analyze_main
from grasp_safety_filter.control.safety_filter import FilterStatus
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder, read_bag
from grasp_safety_filter.runner import analyze_bag, build_endpoints, run, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
STEPS = 30
DT = 0.001


class FailingFilter:
    """Wraps a SafetyFilter; its answers on the given calls carry a failed QP status."""

    def __init__(self, core, failures: dict[int, FilterStatus]):
        self.core = core
        self.failures = failures
        self.calls = 0

    def solve(self, state, u_nom):
        self.calls += 1
        result = self.core.solve(state, u_nom)
        failure = self.failures.get(self.calls)
        return result if failure is None else dataclasses.replace(result, status=failure)

    def __getattr__(self, name):
        return getattr(self.core, name)


def corrupt(msg):
    """Make a joint state the filter must reject (a NaN position)."""
    msg.position = np.r_[np.nan, msg.position[1:]]
    return msg


def wall_clock(msg) -> float:
    """Return a steady clock that advances with the run: the message's stamp, s."""
    return m.header_stamp_ns(msg) * 1e-9


#: Watchdog calls after the end of the run (each a fallback and its status).
AFTER_END_WATCHDOG_CALLS = 3


def record_faulty_run(bag_path: Path) -> None:
    """Record a lockstep run whose filter meets failed QPs, bad input and missing input.

    Wired as the runner wires the endpoints, except that the filter receives a corrupt
    joint state at t_0 (nothing accepted yet: fallback) and at t_10..t_12 (held), its QP
    "fails" on its 5th and 6th solve, and its watchdog finds no input twice after t_20.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msgs = m.MessageNamespace.from_typestore(typestore)
    sim, nominal, safety_filter = build_endpoints(
        RunOptions(CONFIG, 'filtered', duration=STEPS * DT), msgs
    )
    safety_filter.filter = FailingFilter(
        safety_filter.filter,
        {5: FilterStatus.FALLBACK_NOMINAL, 6: FilterStatus.FALLBACK_LAST_GOOD},
    )
    corrupt_steps = {0, 10, 11, 12}
    watchdog_step = 20

    def filter_joint_states(msg):
        step = round(wall_clock(msg) / DT)
        outgoing = safety_filter.on_joint_states(
            corrupt(msg) if step in corrupt_steps else msg, wall=wall_clock(msg)
        )
        if step == watchdog_step:
            # The steady clock jumps past the hold timeout with nothing more received;
            # the node clock stands at the last tick (the simulator takes no such command).
            late = wall_clock(msg) + safety_filter.hold.hold_timeout
            for k in (1, 2):
                outgoing += safety_filter.watchdog(late + k * 0.02, now=(step - 1) * DT)
        return outgoing

    def filter_input(handler):
        return lambda msg: handler(msg, wall=wall_clock(msg))

    subscribers = {
        topics.JOINT_STATES: [nominal.on_joint_states, filter_joint_states],
        topics.OBJECT_ODOM: [nominal.on_odom, filter_input(safety_filter.on_odom)],
        topics.EFFORT_NOMINAL: [filter_input(safety_filter.on_effort_nominal)],
        topics.EFFORT_COMMAND: [sim.on_command],
    }
    with BagRecorder(bag_path, typestore=typestore) as bag:
        queue = deque(sim.start())
        while queue:
            topic, stamp_ns, msg = queue.popleft()
            data = bag.write(topic, stamp_ns, msg)
            for handler in subscribers.get(topic, []):
                queue.extend(handler(typestore.deserialize_cdr(data, msg.__msgtype__)))
        # The run is over and the filter's inputs stop: its watchdog falls back until the
        # node is shut down. Not a fault of the run.
        for k in range(AFTER_END_WATCHDOG_CALLS):
            for topic, stamp_ns, msg in safety_filter.watchdog(1e6 + 0.02 * k, now=STEPS * DT):
                bag.write(topic, stamp_ns, msg)
    assert sim.finished and sim.stop_reason == 'duration'


def test_summary_counts_failed_rejected_and_watchdog_ticks_from_the_bag(tmp_path):
    bag = tmp_path / 'bag'
    record_faulty_run(bag)
    run_data = load_run(bag)
    summary = summarize(run_data)
    counts = summary['filter']
    # One status per tick stamp, t_0..t_N; the watchdog's are counted apart.
    assert counts['steps'] == STEPS + 1
    assert counts['failed_steps'] == 2
    assert counts['rejected_steps'] == 4
    assert counts['watchdog_fallbacks'] == 2
    assert counts['watchdog_statuses_after_end'] == AFTER_END_WATCHDOG_CALLS
    statuses = counts['statuses']
    assert statuses['fallback_nominal'] == 1
    assert statuses['fallback_last_good'] == 1
    assert statuses['input_fallback'] == 1  # t_0: no safe command to hold yet
    assert statuses['input_held'] == 3
    assert sum(statuses.values()) == counts['steps']
    assert run_data.watchdog_statuses == {'input_fallback': 2}
    assert summary['mode'] == 'filtered'
    assert summary['missed_start'] == {}
    # The watchdog's fallbacks carry the last tick's stamp: the tick's own command is kept.
    stamp = round(0.019e9)
    sent = [
        m.effort_from_msg(msg, run_data.joint_names).effort
        for _, msg in read_bag(bag, topics=[topics.EFFORT_COMMAND])[topics.EFFORT_COMMAND]
        if m.header_stamp_ns(msg) == stamp
    ]
    assert len(sent) == 3 and not np.allclose(sent[0], sent[-1])
    (k,) = np.flatnonzero(np.round(run_data.t_command * 1e9) == stamp)
    np.testing.assert_array_equal(run_data.u_command[k], sent[0])


# ----------------------------------------------------------------------------------------
# A recording that missed the start of the run


@pytest.fixture(scope='module')
def runner_bag(tmp_path_factory):
    """Run a short filtered run with the runner; return its bag and summary."""
    result = run(RunOptions(CONFIG, 'filtered', duration=0.03), tmp_path_factory.mktemp('run'))
    return result.bag, result.summary


def copy_dropping_first(source: Path, target: Path, dropped: dict[str, int]) -> None:
    """Copy a bag (to mcap), leaving out the first ``dropped[topic]`` messages of some topics."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    seen: Counter[str] = Counter()
    with Reader(source) as reader:
        writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
        with writer:
            connections = {
                c.id: writer.add_connection(
                    c.topic,
                    c.msgtype,
                    typestore=typestore,
                    offered_qos_profiles=c.ext.offered_qos_profiles,
                )
                for c in reader.connections
            }
            for connection, timestamp, data in reader.messages():
                seen[connection.topic] += 1
                if seen[connection.topic] > dropped.get(connection.topic, 0):
                    writer.write(connections[connection.id], timestamp, data)


def test_a_bag_that_missed_the_start_is_analysed_and_says_so(runner_bag, tmp_path, capsys):
    bag, live_summary = runner_bag
    assert live_summary['missed_start'] == {}
    late = tmp_path / 'late_bag'
    dropped = {topics.EFFORT_COMMAND: 5, topics.JOINT_STATES: 3, topics.CONTACTS: 1}
    copy_dropping_first(bag, late, dropped)

    summary, _ = analyze_bag(late, tmp_path / 'late')
    assert summary['missed_start'] == {
        topic: pytest.approx(n * DT, abs=1e-12) for topic, n in dropped.items()
    }
    assert json.loads((tmp_path / 'late' / 'summary.json').read_text()) == summary
    # Analysed from where the data begin, with the run's own verdict on that part.
    assert summary['completed']
    assert summary['violations'] == live_summary['violations']
    assert summary['filter']['steps'] == live_summary['filter']['steps']

    assert analyze_main([str(late), '--out', str(tmp_path / 'printed')]) == 0
    printed = capsys.readouterr().out
    assert 'recording missed the start of the run' in printed
    assert f'{topics.EFFORT_COMMAND} from 0.005 s' in printed
    assert f'{topics.JOINT_STATES} from 0.003 s' in printed


# ----------------------------------------------------------------------------------------
# The statuses as columns


def test_the_last_status_of_a_stamp_counts_in_stamp_order():
    reader = FilterStatusReader()
    reader.add(2_000_000, {'status': 'solved', 'ticks': '3', 'solve_time_us': '5.0'})
    reader.add(1_000_000, {'status': 'relaxed', 'relaxed': 'true', 'ticks': '2'})
    reader.add(2_000_000, {'status': 'nominal', 'ticks': '3', 'count.nominal': '3'})
    statuses = reader.finish()
    assert statuses.t.tolist() == [0.001, 0.002]
    assert statuses.status == ('relaxed', 'nominal')
    assert statuses.relaxed.tolist() == [True, False]
    assert np.isnan(statuses.times_us).all()  # the re-sent status of t = 2 ms has no time
    assert statuses.counts == {'nominal': 3}


def test_a_status_value_that_is_no_number_is_one_clean_error():
    reader = FilterStatusReader()
    with pytest.raises(m.MessageError, match="'solve_time_us' is not float: 'fast'"):
        reader.add(0, {'status': 'solved', 'solve_time_us': 'fast'})
    with pytest.raises(m.MessageError, match="'ticks' is not int"):
        reader.add(0, {'status': 'solved', 'ticks': '1.5e3'})
