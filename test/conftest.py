"""Every test run talks DDS on a domain of its own, on this machine only.

Set at import, before any test or node process starts, so that the rclpy nodes these tests
start (in-process or as OS processes, which inherit the environment) neither disturb nor
see another ROS graph: not a developer's, not a second test run's.
"""

from __future__ import annotations

import os

#: ROS_DOMAIN_ID range used by test runs (Fast DDS accepts 0..232; 0 is everybody's default).
TEST_DOMAINS = range(101, 201)


def _test_domain() -> int:
    return TEST_DOMAINS[os.getpid() % len(TEST_DOMAINS)]


os.environ['ROS_DOMAIN_ID'] = str(_test_domain())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_LOCALHOST_ONLY', None)  # deprecated on Jazzy; the range above replaces it
os.environ.pop('ROS_STATIC_PEERS', None)
