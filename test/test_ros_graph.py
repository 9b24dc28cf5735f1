"""The three nodes as OS processes over DDS: the runner's stream, from its first tick.

Each graph test starts the console scripts as ``ros2 run`` would (the command lines come
from :mod:`grasp_safety_filter.io.launch_arguments`, as the launch files' nodes do), records
every topic of the topic table with an rclpy recorder (``test/ros_graph.py``) that the
simulator waits for (``start.wait_for_recorder``), and compares the bag with the in-process
lockstep runner's, message by message.
"""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path
import subprocess
import time

import numpy as np
import pytest
from ros_graph import (
    BIN,
    CONFIG,
    LATE_TEXT,
    lockstep_watchdog_counts,
    RESENT_TEXT,
    run_graph,
    run_stream,
    script_command,
    STALL_TOLERANCE,
    stream_differences,
    unexplained_repeats,
    with_overrides,
)

from grasp_safety_filter.analysis.verdict import paper_verdict
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.launch_arguments import NodeLaunch, paper_demo, RECORDER_NODE
from grasp_safety_filter.io.messages import header_stamp_ns
from grasp_safety_filter.runner import record_run, RunOptions
from hand_sim_node.start_up import GraphSnapshot, start_blockers

#: Wall-clock limit of one graph run, s (the graph runs ~80 ticks/s on a shared 2-core box).
RUN_TIMEOUT = 90.0

#: The paper's nominal run stops here, a contact rolled off its fingertip (s).
NOMINAL_STOP = 1.205


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


def runner_bag(
    tmp_path: Path, mode: str, duration: float, overrides: dict | None = None
) -> Path:
    """Record the in-process lockstep runner's run of the same scenario."""
    bag = tmp_path / f'runner_{mode}'
    record_run(RunOptions(CONFIG, mode, duration=duration, overrides=dict(overrides or {})), bag)
    return bag


def analyze(bag: Path, out: Path, paper: bool = True) -> dict:
    """Run ``grasp-analyze BAG --out OUT`` and return its ``summary.json``.

    ``paper``: the bag is of the paper's scenario, whose outcome the analysis then judges.
    """
    result = subprocess.run(
        [str(BIN / 'grasp-analyze'), str(bag), '--out', str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert ('paper outcome reproduced' in result.stdout) == paper, result.stdout
    return json.loads((out / 'summary.json').read_text())


def first_stamps(bag: Path) -> dict[str, int]:
    """Return the first stamp per topic, ns (``/diagnostics`` per status name)."""
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
    unused = (  # and the markers: the graph runs without viz
        topics.OBJECT_REFERENCE,
        topics.OBJECT_POSE,
        topics.OBJECT_TRUE_ODOM,
        topics.EFFORT_CONTROLLER_COMMANDS,
        topics.MARKERS,
    )
    expected = {spec.name for spec in topics.TOPICS if spec.name not in unused} - {
        topics.DIAGNOSTICS
    } | {f'{topics.DIAGNOSTICS}[safety_filter]'}
    assert expected <= set(stamps), sorted(set(expected) - set(stamps))
    assert {key: stamps[key] for key in expected} == dict.fromkeys(expected, 0)


def demo_nodes(mode: str, duration: float) -> list[NodeLaunch]:
    """Return the launch file's nodes, the filter tolerant of scheduling stalls."""
    sim, nominal, safety_filter = paper_demo(
        CONFIG, filter_on=mode == 'filtered', record=True, duration=duration
    )
    return [sim, nominal, with_overrides(safety_filter, **STALL_TOLERANCE)]


def graph_and_runner(tmp_path: Path, mode: str, duration: float, **graph: object):
    nodes = demo_nodes(mode, duration)
    run = run_graph(tmp_path / 'graph', nodes, RUN_TIMEOUT, **graph)
    assert all(code == 0 for code in run.returncodes.values()), (run.returncodes, run.logs)
    return run, runner_bag(tmp_path, mode, duration)


def assert_same_stream(graph_bag: Path, reference: Path) -> None:
    """Check that the graph's stream is the runner's, exactly, without the watchdog's repeats."""
    repeats: dict[str, int] = {}
    assert stream_differences(graph_bag, reference, atol=0.0, repeats=repeats) == []
    watchdog = lockstep_watchdog_counts(graph_bag)
    resent, late = watchdog[RESENT_TEXT], watchdog[LATE_TEXT]
    assert unexplained_repeats(repeats, resent, late) == [], (repeats, watchdog)


def test_filtered_graph_records_the_runner_stream_from_the_first_tick(tmp_path):
    run, reference = graph_and_runner(tmp_path, 'filtered', 0.3)
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)
    during, _ = run_stream(run.bag)
    assert len(during[topics.EFFORT_COMMAND]) == 301
    assert "recorder 'rosbag2_recorder' connected: starting the run" in run.logs
    assert '-p' in run.logs.split()  # the overrides as ros2 run users give them
    summary = analyze(run.bag, tmp_path / 'analysis')
    assert summary['mode'] == 'filtered'
    assert summary['completed'] and summary['t_end'] == pytest.approx(0.3)
    assert summary['missed_start'] == {}
    assert paper_verdict('filtered', summary)[0]


def test_nominal_graph_reproduces_the_paper_failure_tick_by_tick(tmp_path):
    run, reference = graph_and_runner(tmp_path, 'nominal', 15.0)
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)
    # enabled: false beat the parameter file's safety_filter_node section: u* = u_nom.
    during, _ = run_stream(run.bag)
    nominal = {header_stamp_ns(m): np.array(m.effort) for m in during[topics.EFFORT_NOMINAL]}
    commands = [(header_stamp_ns(m), np.array(m.effort)) for m in during[topics.EFFORT_COMMAND]]
    assert len({stamp for stamp, _ in commands}) == round(NOMINAL_STOP / 0.001) + 1
    assert all(np.array_equal(u, nominal[stamp]) for stamp, u in commands)
    summary = analyze(run.bag, tmp_path / 'analysis')
    assert summary['mode'] == 'nominal'
    assert summary['stop_reason'] == 'fingertip_workspace'
    assert summary['t_end'] == pytest.approx(NOMINAL_STOP)
    assert summary['missed_start'] == {}
    ok, verdict = paper_verdict('nominal', summary)
    assert ok, verdict


def test_soft_finger_graph_records_the_runner_stream_with_the_torsions(tmp_path):
    """Soft fingers through every node's parameters: the graph is the runner, exactly."""
    soft = {'model.torsional_friction': 0.005}
    nodes = [with_overrides(node, **soft) for node in demo_nodes('filtered', 0.2)]
    run = run_graph(tmp_path / 'graph', nodes, RUN_TIMEOUT)
    assert all(code == 0 for code in run.returncodes.values()), (run.returncodes, run.logs)
    assert_same_stream(run.bag, runner_bag(tmp_path, 'filtered', 0.2, soft))
    contacts = read_bag(run.bag)[topics.CONTACTS]
    assert [n for n in contacts[-1][1].name if n.endswith('/torsion')] == [
        f'finger{i}/torsion' for i in (1, 2, 3)
    ]
    # Not the paper's scenario (its contacts are soft), so its outcome is not judged.
    summary = analyze(run.bag, tmp_path / 'analysis', paper=False)
    assert summary['completed'] and summary['violations']['slip']['count'] == 0


def test_simulator_waits_for_a_recorder_that_starts_late(tmp_path):
    # The overrides as launch_ros passes them: a parameter file with each node's section
    # (duration: 0.05 beats the paper file's hand_sim_node section).
    run, reference = graph_and_runner(
        tmp_path, 'filtered', 0.05, recorder_delay=5.0, overrides_as_file=True
    )
    assert '_overrides.yaml' in run.logs and '-p' not in run.logs.split()
    assert f"waiting to start the run for recorder '{RECORDER_NODE}' subscribed to" in run.logs
    assert_bag_starts_at_the_first_tick(run.bag)
    assert_same_stream(run.bag, reference)


def test_the_bag_streams_are_compared_exactly():
    """The comparison itself tells a perturbed message apart (no vacuous equality)."""
    from ros_graph import _compare

    differences: list[str] = []
    _compare(np.array([1.0, 2.0]), np.array([1.0, 2.0 + 1e-9]), 'x', 1e-12, differences)
    _compare('a', 'b', 'name', 1e-12, differences)
    _compare([1.0], [1.0, 2.0], 'list', 1e-12, differences)
    assert len(differences) == 3, differences


def test_repeats_are_explained_by_the_states_published_again():
    """A slow answer: the state published again, answered twice, the second answer late."""
    js, odom, command = topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_COMMAND
    slow_answer = {js: 1, odom: 1, command: 1, f'{topics.DIAGNOSTICS}[hand_sim]': 2}
    assert unexplained_repeats(slow_answer, resent=1, late=1) == []
    lost_answer = {js: 2, odom: 2, command: 2}  # two answers lost, the third applied
    assert unexplained_repeats(lost_answer, resent=2, late=0) == []
    assert unexplained_repeats({}, resent=0, late=0) == []
    # A command late without a state published again, or a state repeated without one.
    assert unexplained_repeats(slow_answer, resent=1, late=2) != []
    assert unexplained_repeats({js: 1, odom: 1}, resent=0, late=0) != []
    assert unexplained_repeats({js: 1, odom: 1, command: 2}, resent=1, late=0) != []
    assert unexplained_repeats({topics.CONTACTS: 1}, resent=0, late=0) != []


# ----------------------------------------------------------------------------------------
# A planner over DDS

#: Barrier gains that let the planner's motion through (docs/paper_runs.md: the paper's cubic
#: barriers are so flat below 1 rad that the filter pins the object's acceleration down).
FEASIBLE_BARRIERS = {'barrier.alpha1.gain': 10.0, 'barrier.alpha2.gain': 10.0}
RISE, YAW, MOVE_TIME, STOP_AFTER, HORIZON, PLAN_DURATION = 0.01, 0.1, 0.5, 0.55, 0.05, 1.2


def reference_at(references: list, t: float):
    """Return the planner's reference in force at ``t`` (the newest message stamped <= t)."""
    started = [r for r in references if r.t <= t + 1e-12]
    return started[-1].sample(t) if started else None


def yaw_of(R: np.ndarray) -> float:
    return float(np.arctan2(R[1, 0], R[0, 0]))


def test_planner_drives_the_object_and_a_silent_planner_leaves_it_held(tmp_path):
    from grasp_safety_filter.io.messages import (
        diagnostics_from_msg,
        odometry_from_msg,
        reference_from_msg,
    )
    from grasp_safety_filter.io.schemas import load_node_parameters

    sim, nominal, safety_filter = demo_nodes('filtered', PLAN_DURATION)
    nominal = with_overrides(nominal, **{'reference.source': 'topic'})
    safety_filter = with_overrides(safety_filter, **FEASIBLE_BARRIERS)
    p0 = load_node_parameters(CONFIG, 'hand_sim_node')['initial.object_position']
    planner = script_command(
        'planner',
        '--initial-position', *map(str, p0),
        '--rise', str(RISE), '--yaw', str(YAW), '--move-time', str(MOVE_TIME),
        '--stop-after', str(STOP_AFTER), '--horizon', str(HORIZON),
    )  # fmt: skip
    run = run_graph(
        tmp_path / 'graph', [sim, nominal, safety_filter], RUN_TIMEOUT, extra={'planner': planner}
    )
    assert all(code == 0 for code in run.returncodes.values()), (run.returncodes, run.logs)
    during, _ = run_stream(run.bag)
    references = [reference_from_msg(m) for m in during[topics.OBJECT_REFERENCE]]
    assert len(references) >= 40 and references[-1].t <= STOP_AFTER
    last_point = references[-1].t + references[-1].time_from_start[-1]
    odometry = [odometry_from_msg(m) for m in during[topics.OBJECT_ODOM]]
    assert odometry[-1].t == pytest.approx(PLAN_DURATION)

    # Tracking while the planner publishes: within 0.1 mm and 1 mrad of its reference.
    errors, yaw_errors = [], []
    for odom in odometry:
        if odom.t > STOP_AFTER:
            break
        reference = reference_at(references, odom.t)
        if reference is None:
            continue
        errors.append(np.linalg.norm(odom.p_object_in_palm - reference.p_object_in_palm))
        yaw_errors.append(
            abs(yaw_of(odom.R_object_to_palm) - yaw_of(reference.R_object_to_palm))
        )
    assert len(errors) > 500
    assert max(errors) < 1e-4, max(errors)
    assert max(yaw_errors) < 1e-3, max(yaw_errors)
    moved = odometry[round(STOP_AFTER / 0.001)]
    assert moved.p_object_in_palm[2] - p0[2] == pytest.approx(RISE, abs=2e-4)
    assert yaw_of(moved.R_object_to_palm) == pytest.approx(YAW, abs=2e-3)

    # Silent planner: stale once its last point is reference.timeout old, and the pose held.
    statuses = [
        (diagnostics.t, report)
        for diagnostics in map(diagnostics_from_msg, during[topics.DIAGNOSTICS])
        for report in diagnostics.reports
        if report.name == 'nominal_controller'
    ]
    stale = [(t, r) for t, r in statuses if 'holding its last pose' in r.message]
    assert stale, [r.message for _, r in statuses]
    timeout = load_node_parameters(CONFIG, 'nominal_controller_node')['reference.timeout']
    assert stale[0][0] == pytest.approx(last_point + timeout, abs=2e-3)
    assert all(int(r.level) == 1 and r.values['reference.stale'] == 'true' for _, r in stale)
    assert [t for t, _ in statuses if 0.01 < t < stale[0][0]] == []
    assert len(stale) == round((PLAN_DURATION - stale[0][0]) / 0.001) + 1
    held = references[-1].sample(last_point)
    end = odometry[-1]
    assert np.linalg.norm(end.p_object_in_palm - held.p_object_in_palm) < 3e-4
    assert abs(yaw_of(end.R_object_to_palm) - YAW) < 2e-3


# ----------------------------------------------------------------------------------------
# Bad input over DDS, against the safety filter node alone


class Hand:
    """The hand side of a lone safety filter node: simulator and nominal controller in-process.

    Publishes ``/clock``, ``/hand/joint_states``, ``/object/odom`` and
    ``/hand/effort_nominal`` (built by the runner's endpoints with rclpy classes, so that a
    test can corrupt them before sending) and collects ``/hand/effort_command`` and
    ``/diagnostics``.
    """

    INPUTS = (topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_NOMINAL)

    def __init__(self, context) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from grasp_safety_filter.io.messages import MessageNamespace, rclpy_message_class
        from grasp_safety_filter.io.topics import topic_spec
        from grasp_safety_filter.runner import build_endpoints

        self.msgs = MessageNamespace.from_rclpy()
        self.sim, self.nominal, reference_filter = build_endpoints(
            RunOptions(CONFIG, 'filtered'), self.msgs
        )
        self.model = reference_filter.model
        self.node = rclpy.create_node('hand_driver', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.publishers = {}
        for topic in (topics.CLOCK, *self.INPUTS):
            spec = topic_spec(topic)
            self.publishers[topic] = self.node.create_publisher(
                rclpy_message_class(spec.msgtype), topic, spec.qos.to_rclpy()
            )
        self.commands: list = []
        self.statuses: list = []
        for topic, sink in (
            (topics.EFFORT_COMMAND, self.commands),
            (topics.DIAGNOSTICS, self.statuses),
        ):
            spec = topic_spec(topic)
            self.node.create_subscription(
                rclpy_message_class(spec.msgtype), topic, sink.append, spec.qos.to_rclpy()
            )
        self.state = {o.topic: o.msg for o in self.sim.start()}
        self.sent: dict = {}
        self._nominal = None

    def spin_until(self, predicate, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            assert time.monotonic() < deadline, 'no answer from the safety filter node'
            self.executor.spin_once(timeout_sec=0.02)

    def connected(self) -> bool:
        return all(self.publishers[t].get_subscription_count() > 0 for t in self.INPUTS)

    def publish_clock(self, t: float) -> None:
        from grasp_safety_filter.io.messages import clock_to_msg

        self.publishers[topics.CLOCK].publish(clock_to_msg(self.msgs, t))
        self.executor.spin_once(timeout_sec=0.02)  # /clock arrives before the inputs

    def inputs(self) -> dict:
        """Return copies of the current state and the nominal command for it."""
        state = {
            t: copy.deepcopy(self.state[t]) for t in (topics.JOINT_STATES, topics.OBJECT_ODOM)
        }
        out = self.nominal.on_joint_states(state[topics.JOINT_STATES])
        out += self.nominal.on_odom(state[topics.OBJECT_ODOM])
        for o in out:
            if o.topic == topics.EFFORT_NOMINAL:
                self._nominal = o.msg
        return {**state, topics.EFFORT_NOMINAL: copy.deepcopy(self._nominal)}

    def send(self, stamp: float | None = None, corrupt=None, clock: float | None = None):
        """Publish one tick's inputs stamped ``stamp`` (one corrupted); return the answer.

        Returns:
            The commands stamped like the answer, and its ``safety_filter`` status.

        """
        from grasp_safety_filter.io.messages import (
            header_stamp_ns,
            seconds_to_nanoseconds,
            time_to_msg,
        )

        inputs = self.inputs()
        t = self.sim.t if stamp is None else stamp
        for msg in inputs.values():
            msg.header.stamp = time_to_msg(self.msgs, t)
        if corrupt is not None:
            corrupt(inputs)
        self.sent = inputs
        seen = len(self.statuses)
        self.publish_clock(t if clock is None else clock)
        for topic, msg in inputs.items():
            self.publishers[topic].publish(msg)

        t_ns = seconds_to_nanoseconds(t)

        def answer():
            # Not an answer: the filter's input watchdog (no tick for a while, or none yet),
            # or what it still says about earlier ticks (each rejected input gets its own).
            for status_msg in self.statuses[seen:]:
                for report in status_msg.status:
                    if (
                        report.name == 'safety_filter'
                        and all(pair.key != 'input.watchdog' for pair in report.values)
                        and header_stamp_ns(status_msg) >= t_ns
                    ):
                        return header_stamp_ns(status_msg), report
            return None

        self.spin_until(lambda: answer() is not None)
        stamp_ns, report = answer()
        self.spin_until(lambda: any(header_stamp_ns(c) == stamp_ns for c in self.commands))
        commands = [np.array(c.effort) for c in self.commands if header_stamp_ns(c) == stamp_ns]
        return commands, report

    def step(self, command: np.ndarray) -> None:
        """Apply a command stamped with the simulator's time; keep the next state."""
        from grasp_safety_filter.io.messages import effort_to_msg

        joints = list(self.model.joint_names)
        out = self.sim.on_command(effort_to_msg(self.msgs, self.sim.t, joints, command))
        self.state.update({o.topic: o.msg for o in out if o.topic in self.state})

    def valid_tick(self) -> np.ndarray:
        commands, report = self.send()
        assert_accepted(report)
        self.step(commands[-1])
        return commands[-1]


def level(report) -> int:
    return int.from_bytes(report.level, 'little')


def values(report) -> dict[str, str]:
    return {kv.key: kv.value for kv in report.values}


def assert_accepted(report) -> None:
    """Check for a computed command: OK, or WARN only to say input came back after a gap."""
    assert 'input rejected' not in report.message
    assert values(report)['input.mode'] == 'ok'
    # The filter's wall-clock input watchdog may have stood in while the test prepared
    # bad input; the first tick after it says so.
    assert level(report) == 0 or 'input.resumed_after' in values(report), report.message


def test_bad_input_is_held_then_falls_back_and_is_diagnosed(tmp_path):
    import rclpy
    from ros_graph import node_command, Processes

    from grasp_safety_filter.io.launch_arguments import safety_filter_alone

    node = safety_filter_alone(CONFIG, use_sim_time=True)  # safety_filter.launch.py's node
    # Every tick's status, the good ones too: the test reads the answer to each input.
    node = dataclasses.replace(node, overrides={**node.overrides, 'diagnostics.period': 0.0})
    context = rclpy.Context()
    rclpy.init(context=context)
    with Processes(tmp_path / 'logs') as processes:
        processes.start('safety_filter_node', node_command(node, tmp_path))
        hand = Hand(context)
        try:
            hand.spin_until(hand.connected, timeout=30.0)
            time.sleep(1.0)  # let the filter's side of each connection match as well
            hand.publish_clock(0.0)
            u = [hand.valid_tick() for _ in range(3)]

            # NaN in a joint position: the last safe command, WARN, the reason.
            def nan_position(inputs):
                inputs[topics.JOINT_STATES].position[4] = float('nan')

            commands, report = hand.send(corrupt=nan_position)
            assert level(report) == 1 and 'input rejected' in report.message
            assert 'holding the last safe command' in report.message
            assert topics.JOINT_STATES in report.message and 'nan' in report.message.lower()
            assert values(report)['input.mode'] == 'holding'
            assert any(np.array_equal(c, u[-1]) for c in commands)
            hand.step(u[-1])  # the lockstep simulator applies the held command
            u.append(hand.valid_tick())

            # A joint missing by name.
            missing = hand.model.joint_names[5]

            def drop_joint(inputs):
                msg = inputs[topics.JOINT_STATES]
                keep = [k for k, name in enumerate(msg.name) if name != missing]
                msg.name = [msg.name[k] for k in keep]
                for field in ('position', 'velocity', 'effort'):
                    setattr(msg, field, [getattr(msg, field)[k] for k in keep])

            commands, report = hand.send(corrupt=drop_joint)
            assert level(report) == 1 and missing in report.message, report.message
            assert values(report)['input.mode'] == 'holding'
            assert any(np.array_equal(c, u[-1]) for c in commands)
            hand.step(u[-1])
            u.append(hand.valid_tick())
            q_accepted = np.array(hand.sent[topics.JOINT_STATES].position)

            # A stale stamp: 80 ms old on the node's clock (input.max_age 50 ms).
            t_stale = hand.sim.t
            commands, report = hand.send(clock=t_stale + 0.08)
            assert level(report) == 1 and 'stale' in report.message, report.message
            assert any(np.array_equal(c, u[-1]) for c in commands)

            # Still bad after input.hold_timeout (0.1 s): gravity compensation, ERROR.
            t_fallback = t_stale + 0.08 + 0.12
            commands, report = hand.send(stamp=t_fallback, corrupt=nan_position)
            assert level(report) == 2, report.message
            assert 'fallback command: gravity_compensation' in report.message
            assert values(report)['input.mode'] == 'fallback'
            limits = np.asarray(hand.model.effort_limits, dtype=float)
            terms = hand.model.hand.terms(q_accepted, np.zeros_like(q_accepted))
            expected = np.clip(terms.gravity_torque, -limits, limits)
            assert any(np.allclose(c, expected, atol=1e-9) for c in commands), commands

            # Good input again: computed commands (the first may note the input gap), OK.
            for k in (1, 2):
                commands, report = hand.send(stamp=t_fallback + 0.001 * k)
                assert_accepted(report)
                assert np.all(np.isfinite(commands[-1]))
                assert not np.allclose(commands[-1], expected)
        finally:
            hand.node.destroy_node()
            hand.executor.shutdown()
            rclpy.try_shutdown(context=context)
