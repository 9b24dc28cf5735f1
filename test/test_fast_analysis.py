"""The analysis's fast paths (packed JointState topics, a forked child) change nothing.

Each is compared with the one-pass read that parses every message (and draws every figure)
in the caller: the same run, the same figure files, the same error.
"""

from __future__ import annotations

from dataclasses import fields
import os
from pathlib import Path
import time

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis import figures, topic_readers
from grasp_safety_filter.analysis.forked import ForkedCall, ForkedCallError
from grasp_safety_filter.analysis.run_data import load_run, RunData, RunDataError
from grasp_safety_filter.io import topics
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.runner import record_run, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


@pytest.fixture(scope='module')
def bag(tmp_path_factory) -> Path:
    """Record the start of the paper's filtered run (some 400 messages)."""
    path = tmp_path_factory.mktemp('fast') / 'bag'
    record_run(RunOptions(CONFIG, 'filtered', duration=0.05), path)
    return path


@pytest.fixture
def readers_made(monkeypatch) -> list[bool]:
    """Split every bag; record the ``packed`` argument of each TopicReaders made."""
    monkeypatch.setattr(topic_readers, 'MIN_SPLIT_MESSAGES', 0)
    made: list[bool] = []
    original = topic_readers.TopicReaders.__init__

    def init(self, scenario, margins, packed=False):
        made.append(packed)
        original(self, scenario, margins, packed)

    monkeypatch.setattr(topic_readers.TopicReaders, '__init__', init)
    return made


def parsed_load(bag: Path) -> RunData:
    """``load_run`` parsing every message in one pass (no packing, no child)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(topic_readers, 'PACKED_TOPICS', {})
        patch.setattr(topic_readers, 'MIN_SPLIT_MESSAGES', 10**12)
        return load_run(bag)


def assert_same_run(fast: RunData, parsed: RunData) -> None:
    for entry in fields(RunData):
        a, b = getattr(fast, entry.name), getattr(parsed, entry.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), entry.name
        elif entry.name == 'tracking':
            for part in fields(a):
                assert np.array_equal(getattr(a, part.name), getattr(b, part.name)), part.name
        elif entry.name == 'filter_statuses':
            for part in fields(a):
                x, y = getattr(a, part.name), getattr(b, part.name)
                if isinstance(x, np.ndarray):
                    assert np.array_equal(x, y, equal_nan=True), part.name
                else:
                    assert x == y, part.name
        else:
            assert a == b, entry.name


def edited_copy(source: Path, target: Path, edit, left_out: tuple[str, ...] = ()) -> None:
    """Copy a bag but ``left_out``, each ``/hand/contacts`` message through ``edit``."""
    with Reader(source) as reader:
        records = [
            (c.topic, c.msgtype, t, bytes(d))
            for c, t, d in reader.messages()
            if c.topic not in left_out
        ]
    with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        index = 0
        for topic, msgtype, stamp, data in records:
            if topic == topics.CONTACTS:
                msg = TYPESTORE.deserialize_cdr(data, msgtype)
                edit(index, msg)
                index += 1
                data = bytes(TYPESTORE.serialize_cdr(msg, msgtype))
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(connections[topic], stamp, data)


def test_the_packed_and_forked_read_is_the_parsed_read(bag, readers_made):
    fast = load_run(bag)
    assert readers_made == [True], 'the fast path fell back to the parsers'
    assert fast.tracking is not None and fast.barriers is not None
    assert_same_run(fast, parsed_load(bag))


def test_reordered_contact_entries_are_read_by_the_parsers(bag, tmp_path, readers_made):
    def reverse_third(index, msg):
        if index == 3:
            msg.name, msg.position, msg.velocity = (
                msg.name[::-1],
                msg.position[::-1].copy(),
                msg.velocity[::-1].copy(),
            )

    edited_copy(bag, tmp_path / 'reordered', reverse_third)
    run = load_run(tmp_path / 'reordered')
    assert readers_made == [True, False]  # packed refused the topic: parsed again
    assert_same_run(run, parsed_load(bag))


def test_a_bag_without_commands_is_read_packed(bag, tmp_path, readers_made):
    edited_copy(bag, tmp_path / 'nominal', lambda index, msg: None, (topics.EFFORT_COMMAND,))
    run = load_run(tmp_path / 'nominal')
    assert readers_made == [True]
    assert run.t_command.shape == (0,) and run.u_command.shape == (0, len(run.joint_names))
    assert_same_run(run, parsed_load(tmp_path / 'nominal'))


def test_a_non_finite_contact_value_raises_the_parsers_error(bag, tmp_path, readers_made):
    def nan_in_fifth(index, msg):
        if index == 5:
            msg.position = msg.position.copy()
            msg.position[0] = np.nan

    edited_copy(bag, tmp_path / 'nan', nan_in_fifth)
    with pytest.raises(RunDataError) as expected:
        parsed_load(tmp_path / 'nan')
    readers_made.clear()
    with pytest.raises(RunDataError) as raised:
        load_run(tmp_path / 'nan')
    assert str(raised.value) == str(expected.value)
    assert "'position' of" in str(raised.value) and str(tmp_path / 'nan') in str(raised.value)
    assert readers_made == [True, False]


def test_a_forked_call_gives_its_result_or_fails_cleanly():
    with ForkedCall(lambda: {'rows': np.arange(5)}) as call:
        assert np.array_equal(call.result()['rows'], np.arange(5))

    def raises():
        raise ValueError('bad input')

    with ForkedCall(raises) as call, pytest.raises(ForkedCallError, match='bad input'):
        call.result()
    with ForkedCall(lambda: os._exit(3)) as call, pytest.raises(ForkedCallError):
        call.result()


def test_a_forked_call_that_hangs_is_given_up_and_killed(monkeypatch):
    monkeypatch.setattr(ForkedCall, 'least_wait', 0.5)
    started = time.monotonic()
    with ForkedCall(lambda: time.sleep(60)) as call:
        with pytest.raises(ForkedCallError, match='no result in'):
            call.result()
    assert time.monotonic() - started < 10.0


def test_figures_drawn_beside_are_the_figures_drawn_alone(bag, tmp_path, monkeypatch):
    run = load_run(bag)
    model, _ = GraspModel.from_parameter_file(CONFIG)
    beside = figures.plot_run(run, tmp_path / 'beside', model=model)
    monkeypatch.setattr(figures, 'FORKED_FIGURES', ())
    alone = figures.plot_run(run, tmp_path / 'alone', model=model)
    assert [p.name for p in beside] == [p.name for p in alone] == list(figures.FIGURE_FILES)
    for a, b in zip(beside, alone, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
