"""``grasp-record``: a rosbag2 bag of the topic table without rosbag2, closed on a signal."""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest
from rosbags.highlevel import AnyReader

from grasp_safety_filter.io import topics

RECORD = Path(sys.executable).with_name('grasp-record')


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_a_signal_closes_a_readable_bag_with_every_topic(tmp_path, stop):
    bag = tmp_path / 'bag'
    process = subprocess.Popen(
        [str(RECORD), str(bag)],
        env=dict(os.environ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 30.0
        while not (bag / 'metadata.yaml').exists() and not list(bag.glob('*')):
            assert time.monotonic() < deadline and process.poll() is None, 'no bag opened'
            time.sleep(0.05)
        time.sleep(0.5)
        process.send_signal(stop)
        _, stderr = process.communicate(timeout=30.0)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert 'Traceback' not in stderr
    with AnyReader([bag]) as reader:
        recorded = {c.topic: c.msgtype for c in reader.connections}
    assert recorded == {spec.name: spec.msgtype for spec in topics.TOPICS}


#: A recorder function wrapped so that the process signals itself inside its first call.
SET_UP_STEPS = ['make_executor', 'rclpy_message_class']

SIGNALLED_RECORDER = """
import os, signal, sys, time
from grasp_safety_filter import console
from grasp_safety_filter.nodes import recorder_node

step, signum, bag = sys.argv[1], int(sys.argv[2]), sys.argv[3]
original = getattr(recorder_node, step)
calls = []

def signalled(*args, **kwargs):
    if not calls:
        os.kill(os.getpid(), signum)
        time.sleep(0.3)  # the handler runs here, in the middle of the set-up
    calls.append(1)
    return original(*args, **kwargs)

setattr(recorder_node, step, signalled)
sys.exit(console.record([bag]))
"""


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
@pytest.mark.parametrize('step', SET_UP_STEPS)
def test_a_signal_during_set_up_still_closes_a_readable_bag(tmp_path, step, stop):
    """Subscribing imports each message type's support: a signal there must not be lost."""
    bag = tmp_path / 'bag'
    result = subprocess.run(
        [sys.executable, '-c', SIGNALLED_RECORDER, step, str(int(stop)), str(bag)],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    with AnyReader([bag]) as reader:
        recorded = {c.topic: c.msgtype for c in reader.connections}
    assert recorded == {spec.name: spec.msgtype for spec in topics.TOPICS}


def test_an_existing_bag_directory_is_refused(tmp_path):
    result = subprocess.run(
        [str(RECORD), str(tmp_path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 2
    assert 'exists already' in result.stderr
