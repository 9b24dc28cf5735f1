"""Input parses shared by the in-process subscribers of one message (nodes.shared_parse)."""

from __future__ import annotations

from collections import deque
import copy
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.nodes.shared_parse import parse_directly, SharedParse
from grasp_safety_filter.runner import _subscribers, build_endpoints, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = m.MessageNamespace.from_typestore(TYPESTORE)
NAMES = ('j0', 'j1')


def joint_state(position=(0.1, 0.2)):
    return m.joint_state_to_msg(MSGS, 0.5, list(NAMES), np.array(position), np.zeros(2), None)


class CountingParser:
    """joint_state_from_msg, counting its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, msg, names, source):
        self.calls += 1
        return m.joint_state_from_msg(msg, names, source)


def test_one_message_is_parsed_once_and_its_arrays_are_read_only():
    parse, parser = SharedParse(), CountingParser()
    msg = joint_state()
    first = parse(parser, msg, NAMES, 'js')
    second = parse(parser, msg, NAMES, 'js')
    assert second is first and parser.calls == 1
    direct = parse_directly(m.joint_state_from_msg, msg, NAMES, 'js')
    assert first.t == direct.t and direct.effort is None and first.effort is None
    np.testing.assert_array_equal(first.position, direct.position)
    np.testing.assert_array_equal(first.velocity, direct.velocity)
    assert direct.position.flags.writeable
    with pytest.raises(ValueError, match='read-only'):
        first.position[0] = 1.0


def test_another_message_or_other_arguments_are_parsed_again():
    parse, parser = SharedParse(), CountingParser()
    msg = joint_state()
    first = parse(parser, msg, NAMES, 'js')
    equal_copy = copy.deepcopy(msg)
    assert parse(parser, equal_copy, NAMES, 'js') is not first
    assert parse(parser, equal_copy, NAMES, 'other source') is not first
    assert parser.calls == 3


def test_a_message_that_does_not_parse_is_refused_every_time():
    parse, parser = SharedParse(), CountingParser()
    msg = joint_state(position=(np.nan, 0.2))
    for _ in range(2):
        with pytest.raises(m.MessageError, match="'position' of 'j0' is nan"):
            parse(parser, msg, NAMES, 'js')
    assert parser.calls == 2


def test_the_runner_s_controllers_share_the_parse_of_each_state_message():
    """Wired as record_run wires them: each state message parsed once, the same answers."""
    options = RunOptions(CONFIG, 'filtered', duration=0.005)
    shared = SharedParse()
    calls: list[tuple[str, int]] = []
    received_messages = []  # kept alive: their ids are not reused
    original = SharedParse.__call__

    def counting(self, parser, msg, *args):
        calls.append((parser.__name__, id(msg)))
        received_messages.append(msg)
        return original(self, parser, msg, *args)

    outputs = {}
    for name, parse in (('shared', shared), ('own', None)):
        endpoints = build_endpoints(options, MSGS, parse)
        subscribers = _subscribers(*endpoints)
        queue, stream = deque(endpoints[0].start()), []
        SharedParse.__call__ = counting
        try:
            while queue:
                topic, stamp_ns, msg = queue.popleft()
                data = bytes(TYPESTORE.serialize_cdr(msg, msg.__msgtype__))
                stream.append((topic, stamp_ns, data))
                if topic in subscribers:
                    received = TYPESTORE.deserialize_cdr(data, msg.__msgtype__)
                    for handler in subscribers[topic]:
                        queue.extend(handler(received))
        finally:
            SharedParse.__call__ = original
        outputs[name] = [s for s in stream if s[0] != topics.DIAGNOSTICS]
    # Same messages, byte for byte (the timing values of the statuses aside).
    assert outputs['shared'] == outputs['own']
    # Each joint state and odometry went through the shared parse twice (once per
    # controller), as the same message object.
    per_message = {}
    for parser, msg_id in calls:
        per_message.setdefault((parser, msg_id), 0)
        per_message[parser, msg_id] += 1
    assert {p for p, _ in per_message} == {'joint_state_from_msg', 'odometry_from_msg'}
    assert set(per_message.values()) == {2}
    assert len(per_message) == 2 * 6  # t_0 .. t_5
