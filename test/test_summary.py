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
from grasp_safety_filter.analysis.report import verdict_document
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import first_violated_by, summarize
from grasp_safety_filter.analysis.verdict import expected_verdict, run_verdict
from grasp_safety_filter.cli import analyze_main
from grasp_safety_filter.control.safety_filter import FilterStatus
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder, read_bag
from grasp_safety_filter.runner import analyze_bag, build_endpoints, record_run, run, RunOptions
from hand_sim_node.event_log import EventLog
from hand_sim_node.events import EventMonitor

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
    joint state at t_10..t_12 (held), its QP
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
    corrupt_steps = {10, 11, 12}
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
    assert counts['rejected_steps'] == 3
    assert counts['watchdog_fallbacks'] == 2
    assert counts['watchdog_statuses_after_end'] == AFTER_END_WATCHDOG_CALLS
    statuses = counts['statuses']
    assert statuses['fallback_nominal'] == 1
    assert statuses['fallback_last_good'] == 1
    assert 'input_fallback' not in statuses  # held within input.hold_timeout
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


# ----------------------------------------------------------------------------------------
# Verdicts: the generic one of every run, the expected one of a scenario that declares it

FAMILIES = ('fingertip_workspace', 'joint_limits', 'slip', 'separation')


def summary_of(
    mode: str = 'nominal',
    t_end: float = 15.0,
    stop_reason: str | None = None,
    violated: dict[str, tuple[int, float, str, str]] | None = None,
    families: tuple[str, ...] = FAMILIES,
) -> dict:
    """Make a summary of a 15 s run; ``violated``: family -> (steps, first t, name, side)."""
    violated = violated or {}
    return {
        'mode': mode,
        'completed': stop_reason is None,
        't_end': t_end,
        'duration_requested': 15.0,
        'stop_reason': stop_reason,
        'violations': {
            family: {
                'count': violated[family][0] if family in violated else 0,
                'first_t': violated[family][1] if family in violated else None,
            }
            for family in families
        },
        'first_violated_by': {
            family: {'name': name, 'side': side}
            for family, (_, _, name, side) in violated.items()
        },
    }


#: The paper's nominal outcome: slip at 0.793 s, a joint limit at 1.107 s, the stop at 1.205 s.
PAPER_NOMINAL = {
    'slip': (400, 0.793, 'finger3', ''),
    'joint_limits': (98, 1.107, 'finger1_joint2', 'upper'),
    'fingertip_workspace': (1, 1.205, 'finger2', 'a_max'),
}

#: name: (expected outcome, summary, held, violated families in order, expected met (None:
#: none expected, 'not judged': interrupted), words of the printed verdict).
VERDICT_CASES = {
    'paper nominal reproduced': (
        'paper',
        summary_of('nominal', 1.205, 'fingertip_workspace', PAPER_NOMINAL),
        False,
        ['fingertip_workspace', 'joint_limits', 'slip'],
        True,
        'paper outcome reproduced',
    ),
    'paper nominal too short': (
        'paper',
        summary_of('nominal', 15.0),
        True,
        [],
        False,
        'paper outcome NOT reproduced: not stopped early',
    ),
    'paper nominal without slip': (
        'paper',
        summary_of(
            'nominal',
            1.205,
            'fingertip_workspace',
            {k: v for k, v in PAPER_NOMINAL.items() if k != 'slip'},
        ),
        False,
        ['fingertip_workspace', 'joint_limits'],
        False,
        'NOT reproduced: not required friction above mu',
    ),
    'paper filtered reproduced': (
        'paper',
        summary_of('filtered'),
        True,
        [],
        True,
        'paper outcome reproduced: ran the full duration; no constraint violated',
    ),
    'paper filtered slipping': (
        'paper',
        summary_of('filtered', violated={'slip': (3, 2.5, 'finger1', '')}),
        False,
        ['slip'],
        False,
        'NOT reproduced: not no constraint violated',
    ),
    'example held': ('none', summary_of('filtered'), True, [], None, None),
    'example slips': (
        'none',
        summary_of('nominal', violated={'slip': (500, 0.0, 'finger1', '')}),
        False,
        ['slip'],
        None,
        None,
    ),
    'example passes a joint limit': (
        'none',
        summary_of('filtered', violated={'joint_limits': (7, 3.25, 'finger4_joint1', 'lower')}),
        False,
        ['joint_limits'],
        None,
        None,
    ),
    'example leaves the fingertip workspace': (
        'none',
        summary_of('nominal', 2.0, 'fingertip_workspace', {
            'fingertip_workspace': (1, 2.0, 'finger3', 'b_min'),
        }),
        False,
        ['fingertip_workspace'],
        None,
        None,
    ),
    'example loses a contact': (
        'none',
        summary_of('nominal', violated={'separation': (2, 4.5, 'finger2', '')}),
        False,
        ['separation'],
        None,
        None,
    ),
    'a family this version does not know': (
        'none',
        summary_of(
            'filtered',
            violated={'object_workspace': (4, 0.5, 'finger1', 'v_max')},
            families=(*FAMILIES, 'object_workspace'),
        ),
        False,
        ['object_workspace'],
        None,
        None,
    ),
    'interrupted': ('none', summary_of('filtered', 3.0, 'interrupted'), False, [], None, None),
    'paper, interrupted': (
        'paper',
        summary_of('nominal', 0.5, 'interrupted', {'slip': (3, 0.25, 'finger1', '')}),
        False,
        ['slip'],
        'not judged',
        'paper outcome not judged: the run was interrupted at 0.500 s',
    ),
}


@pytest.mark.parametrize('case', VERDICT_CASES)
def test_verdicts_of_summaries(case):
    outcome, summary, held, violated, met, words = VERDICT_CASES[case]
    verdict = run_verdict(summary)
    assert verdict.held is held
    assert [f.family for f in verdict.families] == list(summary['violations'])
    assert [f.family for f in verdict.families if f.violated] == sorted(
        violated, key=list(summary['violations']).index
    )
    text = verdict.text()
    assert text.startswith(f'held for the duration: {"yes" if held else "no"} (')
    if summary['completed']:
        assert 'ran 15 s' in text
    else:
        assert f'stopped at {summary["t_end"]:.3f} s of 15 s: {summary["stop_reason"]};' in text
    for family in verdict.families:
        if family.family in violated:
            first = summary['violations'][family.family]['first_t']
            by = summary['first_violated_by'][family.family]
            assert f'first violated at {first:.3f} s by {by["name"]}' in family.first_text()
            assert family.first_text().endswith(f', {by["side"]}' if by['side'] else by['name'])
            assert family.family in text
        else:
            assert family.first_text() == 'never violated'
    expected = expected_verdict(outcome, summary['mode'], summary)
    if met is None:
        assert expected is None
    else:
        assert expected.met is (None if met == 'not judged' else met)
        assert words in expected.text
    document = verdict_document(verdict, expected)
    assert set(document['first_violations']) == set(violated)
    assert ('reproduced' in document) is (met is not None)
    assert document.get('reproduced') is (None if met == 'not judged' else met)


def test_an_unknown_expected_outcome_is_refused():
    with pytest.raises(ValueError, match=r"expected_outcome: expected one of .*got 'papr'"):
        expected_verdict('papr', 'nominal', summary_of())


def test_the_first_violation_of_each_family_names_its_contact_or_joint():
    names = ['j1', 'j2', 'j3']
    monitor = EventMonitor(
        np.full(3, -1.0), np.full(3, 1.0), (-1.0, 1.0, -1.0, 1.0), 0.5, names, ['c1', 'c2']
    )
    log = EventLog()
    q_of = {0.0: [0.0, 0.0, 0.0], 0.1: [0.0, 1.5, 0.0], 0.2: [-2.0, 1.5, 2.0]}
    # c2 slips from 0.1 s on (|f_t| / f_n = 1 > 0.5); at 0.2 s j1 and j3 pass theirs too.
    for t, q in q_of.items():
        force = np.array([0.0, 0.0, 1.0, 1.0 if t else 0.0, 0.0, 1.0])
        margins = monitor.margins_at(t, np.array(q), np.zeros((2, 2)), force)
        log.record(margins, monitor.events(margins))
    assert first_violated_by(log) == {
        'joint_limits': {'name': 'j2', 'side': 'upper'},
        'slip': {'name': 'c2', 'side': ''},
    }


PAPER_BAG_CASES = {
    # The paper's scenario, too short to fail: its expected outcome is not met.
    'paper, 50 ms': ({}, None, 1, 'paper outcome NOT reproduced'),
    # Another friction coefficient is another scenario: no outcome is expected of it.
    'paper with another mu': (
        {'model.friction_coefficient': 1.2},
        None,
        0,
        'not checked: the bag records another scenario (differing in friction_coefficient)',
    ),
    # A scenario file of another hand for this bag: a user error.
    'another hand named': ({}, 'four_finger_box.yaml', 2, None),
}


@pytest.mark.parametrize('case', PAPER_BAG_CASES)
def test_grasp_analyze_judges_a_bag_by_the_scenario_it_records(case, tmp_path, capsys):
    overrides, config, code, words = PAPER_BAG_CASES[case]
    bag = tmp_path / 'bag'
    record_run(RunOptions(CONFIG, 'nominal', duration=0.05, overrides=overrides), bag)
    extra = [] if config is None else ['--config', str(CONFIG.parent / config)]
    assert analyze_main([str(bag), '--out', str(tmp_path / 'out'), *extra]) == code
    captured = capsys.readouterr()
    if code == 2:
        (line,) = captured.err.strip().splitlines()
        assert line.startswith('grasp-analyze: --config ') and 'the bag records joints' in line
        return
    assert words in captured.out
    assert 'held for the duration: yes' in captured.out
    assert ('paper outcome' in captured.out) is (code == 1)
