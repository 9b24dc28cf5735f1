"""/safety_filter/margins is compact: names once (and when due), values as a float array."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import iter_bag
from grasp_safety_filter.io.margin_stream import MarginDecoder, MarginEncoder, NAMES_PERIOD
from grasp_safety_filter.io.messages import MessageError, MessageNamespace
from grasp_safety_filter.runner import analyze_bag, run, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)
NAMES = ('joint_limits/j1/lower', 'joint_limits/j1/upper', 'no_slip/c1/face0')


def through_cdr(msg):
    data = TYPESTORE.serialize_cdr(msg, msg.__msgtype__)
    return TYPESTORE.deserialize_cdr(data, msg.__msgtype__)


def test_names_go_out_first_on_change_and_once_per_period():
    encoder = MarginEncoder()
    h = np.array([0.1, 0.2, 0.3])
    period = NAMES_PERIOD
    stamps = [0.0, 0.001, 0.5, period - 0.001, period, period + 0.001]
    named = [bool(len(encoder.encode(MSGS, t, NAMES, h).name)) for t in stamps]
    assert named == [True, False, False, False, True, False]
    renamed = (*NAMES[:2], 'no_slip/c1/face1')
    assert len(encoder.encode(MSGS, period + 0.002, renamed, h).name) == 3
    assert len(encoder.encode(MSGS, period + 0.003, renamed, h).name) == 0
    # Back in time (a restarted simulation): named again.
    assert len(encoder.encode(MSGS, 0.0, renamed, h).name) == 3


def test_the_decoder_reads_nameless_messages_against_the_last_names():
    encoder, decoder = MarginEncoder(), MarginDecoder()
    values = np.random.default_rng(7).normal(size=(5, 3))
    decoded = [
        decoder.decode(through_cdr(encoder.encode(MSGS, k * 0.001, NAMES, h)))
        for k, h in enumerate(values)
    ]
    assert all(d.names == NAMES for d in decoded)
    np.testing.assert_array_equal(np.array([d.h for d in decoded]), values)
    assert [d.t for d in decoded] == pytest.approx([k * 0.001 for k in range(5)])
    # No rates were given: none are sent, and none are made up.
    assert all(np.isnan(d.h_dot).all() for d in decoded)


def test_a_late_joiner_skips_nameless_messages_until_the_names_come():
    encoder = MarginEncoder()
    h = np.array([1.0, 2.0, 3.0])
    stream = [encoder.encode(MSGS, t, NAMES, h) for t in (0.0, 0.001, 0.002, NAMES_PERIOD)]
    decoder = MarginDecoder()
    decoded = [decoder.decode(msg) for msg in stream[1:]]
    assert decoded[:2] == [None, None] and decoder.skipped == 2
    assert decoded[2].names == NAMES


def test_a_nameless_message_of_another_length_is_rejected():
    encoder, decoder = MarginEncoder(), MarginDecoder()
    decoder.decode(encoder.encode(MSGS, 0.0, NAMES, np.zeros(3)))
    short = encoder.encode(MSGS, 0.001, NAMES, np.zeros(3))
    short.position = np.zeros(2)
    with pytest.raises(MessageError, match="'position' has 2 entries"):
        decoder.decode(short)


@pytest.fixture(scope='module')
def filtered_run(tmp_path_factory):
    """Record the start of the paper's filtered run."""
    return run(RunOptions(CONFIG, 'filtered', duration=0.1), tmp_path_factory.mktemp('run'))


def test_margins_cost_little_more_than_their_values_in_a_runner_bag(filtered_run):
    sizes: Counter[str] = Counter()
    counts: Counter[str] = Counter()
    with AnyReader([filtered_run.bag]) as reader:
        for connection, _, rawdata in reader.messages():
            sizes[connection.topic] += len(rawdata)
            counts[connection.topic] += 1
    (_, _, first), *_ = iter_bag(filtered_run.bag, topics=[topics.MARGINS])
    rows = len(first.name)
    assert rows > 30  # the paper's grasp: some 60 barrier rows
    per_message = sizes[topics.MARGINS] / counts[topics.MARGINS]
    # 8 bytes per value, a header and the names once: before, 3856 bytes (names every tick,
    # and an all-zero velocity array).
    assert per_message < 8 * rows + 80, per_message


def test_the_analysis_reads_the_compact_margins(filtered_run):
    decoder = MarginDecoder()
    smallest: dict[str, float] = {}
    messages = 0
    for _, _, msg in iter_bag(filtered_run.bag, topics=[topics.MARGINS]):
        data = decoder.decode(msg)
        messages += 1
        for name, h in zip(data.names, data.h, strict=True):
            family = name.split('/', 1)[0]
            smallest[family] = min(smallest.get(family, np.inf), float(h))
    barriers = filtered_run.summary['barriers']
    assert barriers['messages'] == messages == round(0.1 / 0.001) + 1
    assert barriers['unreadable'] == 0
    assert barriers['min_h'] == pytest.approx(smallest, rel=0, abs=0)
    assert set(smallest) >= {'joint_limits', 'no_slip', 'fingertip_workspace'}


def test_a_recording_without_the_first_margins_message_says_what_it_could_not_read(
    filtered_run, tmp_path
):
    late = tmp_path / 'late'
    with Reader(filtered_run.bag) as reader:
        with Writer(late, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            connections = {
                c.id: writer.add_connection(
                    c.topic,
                    c.msgtype,
                    typestore=TYPESTORE,
                    offered_qos_profiles=c.ext.offered_qos_profiles,
                )
                for c in reader.connections
            }
            dropped = False
            for connection, timestamp, data in reader.messages():
                if connection.topic == topics.MARGINS and not dropped:
                    dropped = True
                    continue
                writer.write(connections[connection.id], timestamp, data)
    summary, _ = analyze_bag(late, tmp_path / 'analysis')
    # A 0.1 s run names its rows once, in the message left out.
    assert summary['barriers']['messages'] == 0
    assert summary['barriers']['unreadable'] == round(0.1 / 0.001)
    assert summary['violations'] == filtered_run.summary['violations']
