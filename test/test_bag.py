"""Bag recording: what is written is read back by AnyReader, also after an interrupt."""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2 import WriterError
from rosbags.typesys import get_typestore, Stores
import yaml

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import bag_topics, BagRecorder, iter_bag, read_bag
from grasp_safety_filter.io.interrupts import interrupt_on_signals, signal_name, SignalInterrupt
from grasp_safety_filter.io.messages import ContactData, DiagnosticReport, ObjectReference
from grasp_safety_filter.io.messages.markers import MarkerArrayBuilder
from grasp_safety_filter.io.readme_tables import topic_table_markdown
from grasp_safety_filter.view.markers import MarkerSpec

REPO = Path(__file__).resolve().parent.parent
JOINTS = [f'finger{i}_joint{j}' for i in (1, 2, 3) for j in (1, 2, 3)]
CONTACT_NAMES = ['finger1', 'finger2', 'finger3']
DT = 0.001
STEPS = 20


def tick_messages(recorder: BagRecorder, k: int, rng: np.random.Generator):
    """One lockstep tick's messages, as (topic, message)."""
    msgs = m.MessageNamespace.from_typestore(recorder.typestore)
    t = k * DT
    n = len(CONTACT_NAMES)
    contacts = ContactData(
        t,
        *(rng.normal(size=(n, 2)) for _ in range(2)),
        rng.normal(size=n),
        *(rng.normal(size=(n, 2)) for _ in range(2)),
        rng.normal(size=n),
        rng.normal(size=(n, 3)),
        np.abs(rng.normal(size=n)),
        rng.normal(size=n),
    )
    reference = ObjectReference(np.zeros(3), np.eye(3), np.zeros(6), np.zeros(6))
    # The scenario is latched: published once, at the start of the run.
    scenario = recorder.typestore.types['std_msgs/msg/String'](data='{}')
    return [(topics.SCENARIO, scenario)] * (k == 0) + [
        (topics.CLOCK, m.clock_to_msg(msgs, t)),
        (topics.JOINT_STATES, m.joint_state_to_msg(msgs, t, JOINTS, *rng.normal(size=(3, 9)))),
        (topics.OBJECT_ODOM, m.odometry_to_msg(msgs, t, np.ones(3), np.eye(3), np.ones(6))),
        (topics.OBJECT_POSE, m.pose_stamped_to_msg(msgs, t, np.ones(3), np.eye(3))),
        (topics.OBJECT_TRUE_ODOM, m.odometry_to_msg(msgs, t, np.ones(3), np.eye(3), np.ones(6))),
        (topics.CONTACTS, m.contacts_to_msg(msgs, contacts, CONTACT_NAMES)),
        (topics.OBJECT_REFERENCE, m.reference_to_msg(msgs, t, [0.0], [reference])),
        (
            topics.OBJECT_REFERENCE_SAMPLE,
            m.odometry_to_msg(msgs, t, np.zeros(3), np.eye(3), np.zeros(6)),
        ),
        (topics.EFFORT_NOMINAL, m.effort_to_msg(msgs, t, JOINTS, rng.normal(size=9))),
        (topics.EFFORT_COMMAND, m.effort_to_msg(msgs, t, JOINTS, rng.normal(size=9))),
        (
            topics.EFFORT_CONTROLLER_COMMANDS,
            m.effort_array_to_msg(msgs, np.arange(9)[::-1], rng.normal(size=9)),
        ),
        (topics.MARGINS, m.margins_to_msg(msgs, t, ['a', 'b'], rng.normal(size=2))),
        (
            topics.MARKERS,
            MarkerArrayBuilder(msgs, 'palm').build(
                t, [MarkerSpec('contacts', 0, 'sphere_list', points=rng.normal(size=(3, 3)))]
            ),
        ),
        (
            topics.DIAGNOSTICS,
            m.diagnostics_to_msg(
                msgs, t, DiagnosticReport.create('safety_filter', 0, 'ok', {'k': k})
            ),
        ),
    ]


def stamp_ns(msg) -> int:
    if hasattr(msg, 'markers'):  # a MarkerArray: its markers' stamp
        return m.header_stamp_ns(msg.markers[0])
    if hasattr(msg, 'header'):
        return m.header_stamp_ns(msg)
    if hasattr(msg, 'clock'):
        return m.time_msg_to_nanoseconds(msg.clock)
    return 0  # the scenario, stamped at the run start


def expected_count(topic: str, steps: int = STEPS) -> int:
    return 1 if topic == topics.SCENARIO else steps


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_written_bag_is_read_back_with_topics_types_counts_and_qos(tmp_path, storage):
    path = tmp_path / 'bag'
    rng = np.random.default_rng(0)
    sent_efforts = []
    with BagRecorder(path, storage=storage) as recorder:
        for k in range(STEPS):
            for topic, msg in tick_messages(recorder, k, rng):
                # An unstamped command is recorded at its tick's stamp, as a node publishes it.
                unstamped = topic == topics.EFFORT_CONTROLLER_COMMANDS
                recorder.write(topic, round(k * DT * 1e9) if unstamped else stamp_ns(msg), msg)
                if topic == topics.EFFORT_COMMAND:
                    sent_efforts.append(np.array(msg.effort))
        recorder.set_custom_data('run', 'paper_demo')
    assert recorder.counts == {spec.name: expected_count(spec.name) for spec in topics.TOPICS}

    metadata = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['version'] == 9
    assert metadata['storage_identifier'] == storage
    assert metadata['message_count'] == sum(expected_count(s.name) for s in topics.TOPICS)
    assert metadata['custom_data'] == {'run': 'paper_demo'}

    with AnyReader([path]) as reader:
        recorded = {c.topic: c for c in reader.connections}
        assert set(recorded) == {spec.name for spec in topics.TOPICS}
        for spec in topics.TOPICS:
            connection = recorded[spec.name]
            assert connection.msgtype == spec.msgtype
            assert connection.msgcount == expected_count(spec.name)
            assert connection.ext.serialization_format == 'cdr'
            (qos,) = connection.ext.offered_qos_profiles
            assert qos.history is QosHistory.KEEP_LAST
            assert qos.depth == spec.qos.depth
            assert qos.reliability is QosReliability[spec.qos.reliability.upper()]
            assert qos.durability is QosDurability[spec.qos.durability.upper()]

    info = bag_topics(path)
    assert info[topics.CLOCK].offered_qos[0].reliability is QosReliability.BEST_EFFORT
    assert info[topics.JOINT_STATES].count == STEPS

    bag = read_bag(path)
    for topic, entries in bag.items():
        stamps = [stamp for stamp, _ in entries]
        assert stamps == [round(k * DT * 1e9) for k in range(expected_count(topic))], topic
        if topic != topics.EFFORT_CONTROLLER_COMMANDS:
            assert [stamp_ns(msg) for _, msg in entries] == stamps
    received = [m.effort_from_msg(msg, JOINTS).effort for _, msg in bag[topics.EFFORT_COMMAND]]
    for got, sent in zip(received, sent_efforts, strict=True):
        assert got.tobytes() == sent.tobytes()
    state = m.joint_state_from_msg(bag[topics.JOINT_STATES][3][1], JOINTS)
    assert state.t == 3 * DT


def test_read_bag_and_iter_bag_select_topics(tmp_path):
    path = tmp_path / 'bag'
    with BagRecorder(path) as recorder:
        for k in range(3):
            for topic, msg in tick_messages(recorder, k, np.random.default_rng(k)):
                recorder.write(topic, stamp_ns(msg), msg)
    selected = read_bag(path, topics=[topics.CLOCK, topics.MARGINS])
    assert set(selected) == {topics.CLOCK, topics.MARGINS}
    assert [m.clock_from_msg(msg) for _, msg in selected[topics.CLOCK]] == [0.0, 0.001, 0.002]
    assert list(iter_bag(path, topics=['/not/recorded'])) == []
    timestamps = [stamp for _, stamp, _ in iter_bag(path)]
    assert timestamps == sorted(timestamps)
    assert len(timestamps) == sum(expected_count(spec.name, 3) for spec in topics.TOPICS)


def test_topics_without_messages_are_still_in_the_bag(tmp_path):
    path = tmp_path / 'bag'
    with BagRecorder(path, storage='sqlite3'):
        pass
    bag = read_bag(path)
    assert set(bag) == {spec.name for spec in topics.TOPICS}
    assert all(entries == [] for entries in bag.values())


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('error', [RuntimeError('solver blew up'), KeyboardInterrupt()])
def test_bag_is_closed_and_readable_after_an_exception(tmp_path, storage, error):
    path = tmp_path / 'bag'
    with pytest.raises(type(error)):
        with BagRecorder(path, storage=storage) as recorder:
            for k in range(5):
                for topic, msg in tick_messages(recorder, k, np.random.default_rng(k)):
                    recorder.write(topic, stamp_ns(msg), msg)
            recorder.set_custom_data('interrupted', 'true')
            raise error
    assert not recorder.is_open
    info = bag_topics(path)
    assert {name: topic.count for name, topic in info.items()} == {
        name: expected_count(name, 5) for name in info
    }
    metadata = yaml.safe_load((path / 'metadata.yaml').read_text())
    assert metadata['rosbag2_bagfile_information']['custom_data'] == {'interrupted': 'true'}


def test_write_checks_topic_type_stamp_and_open_state(tmp_path):
    recorder = BagRecorder(tmp_path / 'bag')
    msgs = m.MessageNamespace.from_typestore(recorder.typestore)
    clock = m.clock_to_msg(msgs, 0.0)
    with pytest.raises(RuntimeError, match='not open'):
        recorder.write(topics.CLOCK, 0, clock)
    with recorder:
        with pytest.raises(KeyError, match='/tf'):
            recorder.write('/tf', 0, clock)
        with pytest.raises(TypeError, match='sensor_msgs/msg/JointState'):
            recorder.write(topics.JOINT_STATES, 0, clock)
        with pytest.raises(ValueError, match='stamp_ns'):
            recorder.write(topics.CLOCK, -1, clock)
        with pytest.raises(ValueError, match='stamp_ns'):
            recorder.write(topics.CLOCK, 0.5, clock)
        recorder.write(topics.CLOCK, 0, clock)
    assert bag_topics(tmp_path / 'bag')[topics.CLOCK].count == 1


def test_recorder_refuses_to_overwrite_and_unknown_storage(tmp_path):
    (tmp_path / 'bag').mkdir()
    with pytest.raises(WriterError, match='exists'):
        BagRecorder(tmp_path / 'bag').open()
    with pytest.raises(ValueError, match='storage'):
        BagRecorder(tmp_path / 'other', storage='rosbag1')


def test_signal_during_a_write_waits_until_the_message_is_written(tmp_path):
    path = tmp_path / 'bag'
    previous = signal.getsignal(signal.SIGTERM)
    completed = []
    with interrupt_on_signals():
        recorder = BagRecorder(path)
        msgs = m.MessageNamespace.from_typestore(recorder.typestore)
        with pytest.raises(SignalInterrupt) as interrupt:
            with recorder:
                write = recorder._writer.write

                def write_after_signal(*args):
                    os.kill(os.getpid(), signal.SIGTERM)
                    write(*args)  # still runs: the interrupt is deferred
                    completed.append(args[1])

                recorder._writer.write = write_after_signal
                recorder.write(topics.CLOCK, 7, m.clock_to_msg(msgs, 0.0))
                pytest.fail('the deferred interrupt was not raised after the write')
    assert signal_name(interrupt.value) == 'SIGTERM'
    assert completed == [7]
    assert signal.getsignal(signal.SIGTERM) is previous
    assert [stamp for stamp, _ in read_bag(path)[topics.CLOCK]] == [7]


RECORDING_SCRIPT = textwrap.dedent(
    """
    import sys

    import numpy as np

    from grasp_safety_filter.io import messages as m, topics
    from grasp_safety_filter.io.bag import BagRecorder
    from grasp_safety_filter.io.interrupts import interrupt_on_signals, signal_name

    path, storage = sys.argv[1], sys.argv[2]
    joints = [f'finger{i}_joint{j}' for i in (1, 2, 3) for j in (1, 2, 3)]
    k = 0
    with interrupt_on_signals():
        try:
            with BagRecorder(path, storage=storage) as bag:
                msgs = m.MessageNamespace.from_typestore(bag.typestore)
                try:
                    while True:
                        t = k * 0.001
                        ns = m.seconds_to_nanoseconds(t)
                        bag.write(topics.CLOCK, ns, m.clock_to_msg(msgs, t))
                        state = m.joint_state_to_msg(msgs, t, joints, *np.ones((3, 9)) * k)
                        bag.write(topics.JOINT_STATES, ns, state)
                        k += 1
                        if k == 200:
                            print('recording', flush=True)
                except KeyboardInterrupt:
                    bag.set_custom_data('interrupted', 'true')
                    raise
        except KeyboardInterrupt as interrupt:
            print('interrupted', signal_name(interrupt), k, flush=True)
            sys.exit(130)
    """
)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_run_killed_mid_way_leaves_a_readable_bag(tmp_path, storage, signum):
    script = tmp_path / 'record.py'
    script.write_text(RECORDING_SCRIPT)
    path = tmp_path / 'bag'
    env = {**os.environ, 'PYTHONPATH': str(REPO)}
    process = subprocess.Popen(
        [sys.executable, str(script), str(path), storage],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert process.stdout.readline().strip() == 'recording', process.stderr.read()
        process.send_signal(signum)
        stdout, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130, stderr
    name, ticks = stdout.split()[1:]
    assert name == signal.Signals(signum).name

    metadata = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['custom_data'] == {'interrupted': 'true'}
    bag = read_bag(path)
    clock, states = bag[topics.CLOCK], bag[topics.JOINT_STATES]
    # The interrupt lands between two statements of a tick: the clock may be one message
    # ahead of the states, the states one ahead of the tick counter.
    assert len(clock) - len(states) in (0, 1)
    assert len(states) - int(ticks) in (0, 1)
    assert len(states) >= 200
    assert metadata['message_count'] == len(clock) + len(states)
    stamps = [stamp for stamp, _ in states]
    assert stamps == sorted(stamps)
    last = m.joint_state_from_msg(states[-1][1], JOINTS)
    assert last.position.tolist() == [len(states) - 1.0] * 9


# ----------------------------------------------------------------------------------------
# Topic table


def test_topic_table_names_are_unique_and_types_exist_in_the_jazzy_typestore():
    names = [spec.name for spec in topics.TOPICS]
    assert len(names) == len(set(names))
    store = get_typestore(Stores.ROS2_JAZZY)
    for spec in topics.TOPICS:
        assert spec.name.startswith('/')
        assert spec.msgtype in store.types
        assert spec.publishers
        assert topics.topic_spec(spec.name) is spec
    with pytest.raises(KeyError, match='/hand/joint_states'):
        topics.topic_spec('/joint_states')


def test_every_node_and_conversion_type_is_in_the_table():
    published = {p for spec in topics.TOPICS for p in spec.publishers}
    nodes = {'hand_sim_node', 'nominal_controller_node', 'safety_filter_node'}
    assert nodes | {'grasp_markers_node'} <= published
    expected_types = {
        'sensor_msgs/msg/JointState',
        'nav_msgs/msg/Odometry',
        'geometry_msgs/msg/PoseStamped',
        'std_msgs/msg/Float64MultiArray',
        'trajectory_msgs/msg/MultiDOFJointTrajectory',
        'diagnostic_msgs/msg/DiagnosticArray',
        'rosgraph_msgs/msg/Clock',
        'std_msgs/msg/String',
        'visualization_msgs/msg/MarkerArray',
    }
    assert {spec.msgtype for spec in topics.TOPICS} == expected_types


def test_qos_converts_to_the_rosbags_profile():
    qos = topics.TopicQos('best_effort', 'transient_local', 3).to_rosbags()
    assert qos.reliability is QosReliability.BEST_EFFORT
    assert qos.durability is QosDurability.TRANSIENT_LOCAL
    assert qos.history is QosHistory.KEEP_LAST
    assert qos.depth == 3
    assert topics.CLOCK_QOS.text == 'best_effort, volatile, keep last 1'


@pytest.mark.parametrize(
    ('args', 'match'),
    [
        (('reliable', 'volatile', 0), 'depth'),
        (('reliable', 'volatile', 2.0), 'depth'),
        (('fast', 'volatile', 1), 'reliability'),
        (('reliable', 'persistent', 1), 'durability'),
    ],
)
def test_qos_rejects_unknown_policies(args, match):
    with pytest.raises(ValueError, match=match):
        topics.TopicQos(*args)


def test_topic_table_markdown_lists_every_topic():
    table = topic_table_markdown()
    rows = table.strip().splitlines()
    assert len(rows) == 2 + len(topics.TOPICS)
    for spec, row in zip(topics.TOPICS, rows[2:], strict=True):
        assert f'`{spec.name}`' in row
        assert f'`{spec.msgtype}`' in row
        assert spec.qos.text in row
