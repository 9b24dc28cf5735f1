"""The tests' ROS graphs are invisible from domain 0 and see nothing of it (conftest.py)."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'


def node_names(domain_id: int, seconds: float) -> set[str]:
    """Node names an rclpy context on ``domain_id`` discovers within ``seconds``."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node('isolation_probe', context=context)
    try:
        deadline = time.monotonic() + seconds
        names: set[str] = set()
        while time.monotonic() < deadline:
            names |= set(node.get_node_names())
            if 'safety_filter_node' in names:
                break
            time.sleep(0.1)
        return names
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_the_test_run_has_its_own_domain_and_discovers_on_this_machine_only():
    assert os.environ['ROS_DOMAIN_ID'] not in ('', '0')
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'


def test_a_node_the_tests_start_is_seen_on_the_test_domain_and_not_on_domain_0():
    process = subprocess.Popen(
        [
            str(Path(sys.executable).with_name('safety_filter_node')),
            '--ros-args',
            '--params-file',
            str(CONFIG),
        ],
        env=dict(os.environ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert 'safety_filter_node' in node_names(int(os.environ['ROS_DOMAIN_ID']), 30.0)
        assert 'safety_filter_node' not in node_names(0, 3.0)
    finally:
        process.send_signal(2)
        process.wait(timeout=30)
