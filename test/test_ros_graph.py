"""The three nodes as OS processes over DDS: the runner's stream, from its first tick.

Each graph test starts the console scripts as ``ros2 run`` would (the command lines come
from :mod:`grasp_safety_filter.io.launch_arguments`, as the launch files' nodes do), records
every topic of the topic table with an rclpy recorder (``test/ros_graph.py``) that the
simulator waits for (``start.wait_for_recorder``), and compares the bag with the in-process
lockstep runner's, message by message.
"""

from __future__ import annotations

import json
from pathlib import Path
import subprocess
import time

import numpy as np
import pytest
from ros_graph import BIN, CONFIG, run_graph, run_stream, stream_differences

from grasp_safety_filter.cli import paper_verdict
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.launch_arguments import paper_demo, RECORDER_NODE
from grasp_safety_filter.io.messages import header_stamp_ns
from grasp_safety_filter.runner import record_run, RunOptions
from hand_sim_node.endpoint import GraphSnapshot, start_blockers

#: Wall-clock limit of one graph run, s (the graph runs ~80 ticks/s on a shared 2-core box).
RUN_TIMEOUT = 90.0

#: The paper's nominal run stops here, a contact rolled off its fingertip (s).
NOMINAL_STOP = 1.205

WALL_TIMES: dict[str, float] = {}


# ----------------------------------------------------------------------------------------
# When the simulator starts (pure)

SIM = '/hand_sim_node'
FILTER = '/safety_filter_node'
NOMINAL = '/nominal_controller_node'
RECORDER = f'/{RECORDER_NODE}'
STATE = (topics.JOINT_STATES, topics.OBJECT_ODOM)


def demo_graph(recorder_topics: tuple[str, ...] = (), filter_inputs: bool = True) -> GraphSnapshot:
    """Return the paper demo's graph as the simulator sees it (its own node left out)."""
    subscribers: dict[str, set[str]] = {t: {NOMINAL} for t in STATE}
    if filter_inputs:
        for topic in (*STATE, topics.EFFORT_NOMINAL):
            subscribers.setdefault(topic, set()).add(FILTER)
    publishers = {
        topics.EFFORT_NOMINAL: {NOMINAL},
        topics.EFFORT_COMMAND: {FILTER},
        topics.MARGINS: {FILTER},
        topics.DIAGNOSTICS: {FILTER, NOMINAL},
    }
    for topic in recorder_topics:
        subscribers.setdefault(topic, set()).add(RECORDER)
    return GraphSnapshot(
        publishers={t: frozenset(n) for t, n in publishers.items()},
        subscribers={t: frozenset(n) for t, n in subscribers.items()},
        matched={t: len(subscribers[t]) for t in STATE},
    )


ALL_PUBLISHED = tuple(s.name for s in topics.TOPICS if s.name != topics.OBJECT_REFERENCE)


def test_start_needs_the_filter_subscribed_not_only_its_publishers():
    assert start_blockers(demo_graph()) == []
    # The filter creates its publishers before its subscriptions (it builds its model in
    # between): the state published then would reach the nominal controller only.
    blockers = start_blockers(demo_graph(filter_inputs=False))
    assert blockers == [f'{FILTER} subscribed to {topics.JOINT_STATES}']
    no_nominal = demo_graph()
    no_nominal = GraphSnapshot(
        {**no_nominal.publishers, topics.EFFORT_NOMINAL: frozenset()},
        no_nominal.subscribers,
        no_nominal.matched,
    )
    assert start_blockers(no_nominal) == [
        f'a publisher on {topics.EFFORT_NOMINAL} (for {FILTER})'
    ]
    assert f'a publisher on {topics.EFFORT_COMMAND}' in start_blockers(GraphSnapshot())


def test_start_waits_until_every_node_name_is_known():
    graph = demo_graph()
    unknown = '_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_'
    subscribers = {
        **graph.subscribers,
        topics.JOINT_STATES: frozenset({NOMINAL, FILTER, unknown}),
    }
    blockers = start_blockers(GraphSnapshot(graph.publishers, subscribers, graph.matched))
    assert blockers == [f'the names of the nodes on {topics.JOINT_STATES}']


def test_start_waits_for_the_recorder_on_every_published_topic():
    assert start_blockers(demo_graph(ALL_PUBLISHED), RECORDER_NODE) == []
    assert start_blockers(demo_graph(ALL_PUBLISHED), RECORDER) == []
    # ros2 bag record subscribes to a topic once it has a publisher: no planner, no wait.
    assert topics.OBJECT_REFERENCE not in ALL_PUBLISHED
    late = tuple(t for t in ALL_PUBLISHED if t not in (topics.EFFORT_COMMAND, topics.CLOCK))
    assert start_blockers(demo_graph(late), RECORDER_NODE) == [
        f"recorder '{RECORDER_NODE}' subscribed to {topics.EFFORT_COMMAND}, {topics.CLOCK}"
    ]
    assert start_blockers(demo_graph(late)) == []
    assert start_blockers(demo_graph(ALL_PUBLISHED), 'other_recorder') != []


# ----------------------------------------------------------------------------------------
# Graph runs


def runner_bag(tmp_path: Path, mode: str, duration: float) -> Path:
    """Record the in-process lockstep runner's run of the same scenario."""
    bag = tmp_path / f'runner_{mode}'
    record_run(RunOptions(CONFIG, mode, duration=duration), bag)
    return bag


def analyze(bag: Path, out: Path) -> dict:
    """Run ``grasp-analyze BAG --out OUT`` and return its ``summary.json``."""
    result = subprocess.run(
        [str(BIN / 'grasp-analyze'), str(bag), '--out', str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'paper outcome reproduced' in result.stdout, result.stdout
    return json.loads((out / 'summary.json').read_text())


def first_stamps(bag: Path) -> dict[str, int]:
    """First stamp per topic, ns; ``/diagnostics`` per status name; ``/clock`` its time."""
    stamps: dict[str, int] = {}
    for topic, messages in read_bag(bag).items():
        for _, msg in messages:
            if topic == topics.CLOCK:
                stamp = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
            elif topic == topics.SCENARIO:
                stamp = 0
            else:
                stamp = header_stamp_ns(msg)
            key = topic
            if topic == topics.DIAGNOSTICS:
                key = f'{topic}[{msg.status[0].name}]'
            stamps.setdefault(key, stamp)
    return stamps


def assert_bag_starts_at_the_first_tick(bag: Path) -> None:
    stamps = first_stamps(bag)
    expected = {
        spec.name for spec in topics.TOPICS if spec.name not in (topics.OBJECT_REFERENCE,)
    } - {topics.DIAGNOSTICS} | {f'{topics.DIAGNOSTICS}[safety_filter]'}
    assert expected <= set(stamps), sorted(set(expected) - set(stamps))
    assert {key: stamps[key] for key in expected} == dict.fromkeys(expected, 0)


def graph_and_runner(tmp_path: Path, mode: str, duration: float, **graph: object):
    nodes = paper_demo(CONFIG, filter_on=mode == 'filtered', record=True, duration=duration)
    run = run_graph(tmp_path / 'graph', nodes, RUN_TIMEOUT, **graph)
    assert all(code == 0 for code in run.returncodes.values()), (run.returncodes, run.logs)
    return run, runner_bag(tmp_path, mode, duration)


def assert_same_stream(graph_bag: Path, reference: Path) -> None:
    """Check that the graph's stream is the runner's, exactly, without the watchdog's repeats."""
    repeats: dict[str, int] = {}
    assert stream_differences(graph_bag, reference, atol=0.0, repeats=repeats) == []
    # Each watchdog status comes with one repeated state, nothing else is repeated.
    watchdog = repeats.get(f'{topics.DIAGNOSTICS}[hand_sim]', 0)
    assert repeats.get(topics.JOINT_STATES, 0) == watchdog, repeats
    assert repeats.get(topics.OBJECT_ODOM, 0) == watchdog, repeats
    assert repeats.get(topics.CONTACTS, 0) == 0, repeats


def test_filtered_graph_records_the_runner_stream_from_the_first_tick(tmp_path):
    start = time.monotonic()
    run, reference = graph_and_runner(tmp_path, 'filtered', 0.3)
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)
    during, _ = run_stream(run.bag)
    assert len(during[topics.EFFORT_COMMAND]) == 301
    # Command lines as ros2 run gets them: parameter file and the node's overrides.
    assert "recorder 'rosbag2_recorder' connected: starting the run" in run.logs
    summary = analyze(run.bag, tmp_path / 'analysis')
    assert summary['mode'] == 'filtered'
    assert summary['completed'] and summary['t_end'] == pytest.approx(0.3)
    assert summary['missed_start'] == {}
    assert paper_verdict('filtered', summary)[0]
    WALL_TIMES['filtered 0.3 s'] = time.monotonic() - start


def test_nominal_graph_reproduces_the_paper_failure_tick_by_tick(tmp_path):
    start = time.monotonic()
    run, reference = graph_and_runner(tmp_path, 'nominal', 15.0)
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)
    summary = analyze(run.bag, tmp_path / 'analysis')
    assert summary['mode'] == 'nominal'
    assert summary['stop_reason'] == 'fingertip_workspace'
    assert summary['t_end'] == pytest.approx(NOMINAL_STOP)
    assert summary['missed_start'] == {}
    ok, verdict = paper_verdict('nominal', summary)
    assert ok, verdict
    WALL_TIMES['nominal to 1.205 s'] = time.monotonic() - start


def test_simulator_waits_for_a_recorder_that_starts_late(tmp_path):
    start = time.monotonic()
    run, reference = graph_and_runner(tmp_path, 'filtered', 0.05, recorder_delay=5.0)
    assert f"waiting to start the run for recorder '{RECORDER_NODE}' subscribed to" in run.logs
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)
    WALL_TIMES['late recorder 0.05 s'] = time.monotonic() - start


def test_the_bag_streams_are_compared_exactly():
    """The comparison itself tells a perturbed message apart (no vacuous equality)."""
    from ros_graph import _compare

    differences: list[str] = []
    _compare(np.array([1.0, 2.0]), np.array([1.0, 2.0 + 1e-9]), 'x', 1e-12, differences)
    _compare('a', 'b', 'name', 1e-12, differences)
    _compare([1.0], [1.0, 2.0], 'list', 1e-12, differences)
    assert len(differences) == 3, differences
