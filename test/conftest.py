"""Every test run talks DDS on a domain of its own, on this machine only.

Set at import, before any test or node process starts, so that the rclpy nodes these tests
start (in-process or as OS processes, which inherit the environment) neither disturb nor
see another ROS graph: not a developer's, not a second test run's.
"""

from __future__ import annotations

import os

import pytest

#: ROS_DOMAIN_ID range used by test runs (Fast DDS accepts 0..232; 0 is everybody's default).
TEST_DOMAINS = range(101, 201)


def _test_domain() -> int:
    # pytest-xdist's workers of one run share a parent process: their numbers keep them apart.
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    if worker.startswith('gw'):
        return TEST_DOMAINS[(os.getppid() * 8 + int(worker[2:])) % len(TEST_DOMAINS)]
    return TEST_DOMAINS[os.getpid() % len(TEST_DOMAINS)]


os.environ['ROS_DOMAIN_ID'] = str(_test_domain())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_LOCALHOST_ONLY', None)  # deprecated on Jazzy; the range above replaces it
os.environ.pop('ROS_STATIC_PEERS', None)

#: Tests whose assertions depend on wall-clock time (a driver's rate, a watchdog's timeout, a
#: node's CPU share): ``make test`` runs them on their own after the others, which it runs two
#: at a time. Per module: every test in it (None), or the named ones.
REAL_TIME_TESTS: dict[str, frozenset[str] | None] = {
    'test_real_hand_graph.py': None,
    'test_real_hand_filter.py': None,
    'test_hardware_graph.py': None,
    'test_filter_watchdog.py': None,
    'test_bench_realtime.py': frozenset(
        {'test_filter_mode_over_dds_answers_the_drivers_states'}
    ),
    'test_grasp_markers.py': frozenset(
        {'test_the_node_draws_the_newest_state_at_most_at_its_rate'}
    ),
}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        'markers', 'realtime: asserts on wall-clock time; run alone (see REAL_TIME_TESTS)'
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        module = item.path.name
        if module in REAL_TIME_TESTS:
            names = REAL_TIME_TESTS[module]
            if names is None or item.originalname in names:
                item.add_marker(pytest.mark.realtime)
