"""The machine the figures are taken on: what it is, and its own timing spread.

:func:`machine_info`: versions, CPUs and load. :func:`noise_floor`: on a shared machine a
tick's p99 holds the scheduler and the other processes as well as the tick's own work. A
fixed, deterministic compiled loop (no allocation, no branch on data, the same instructions
every call) timed in thread CPU time has no spread of its own: its p99 over its median is
the machine's. Read next to the node tick's p99, it says how much of that p99 any work of
that size would show here.
"""

from __future__ import annotations

import importlib.metadata
import os
from pathlib import Path
import platform
import time
from typing import Any

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_tools.bench.replay import statistics

#: Distribution packages whose versions the report lists.
VERSIONED_PACKAGES = ('numpy', 'numba', 'scipy', 'osqp', 'cvxpy', 'qpsolvers', 'daqp', 'clarabel')

#: Thread CPU time one call is sized to take, s: about the filter node tick's median.
TARGET_CALL_TIME = 50e-6

#: The logistic map's parameter and start: chaotic, so no iterate repeats and none folds away.
_RATE, _START = 3.9, 0.5


def machine_info() -> dict[str, Any]:
    """Python and package versions, CPU count and model, load average (1, 5, 15 min)."""
    versions = {}
    for package in VERSIONED_PACKAGES:
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = None
    cpu_model = platform.processor() or platform.machine()
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu_model = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load_average: list[float] | None = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load_average = None
    return {
        'python': platform.python_version(),
        'implementation': platform.python_implementation(),
        'platform': platform.platform(),
        'cpu_count': os.cpu_count(),
        'cpu_model': cpu_model,
        'load_average': load_average,
        'packages': versions,
    }


@kernel
def fixed_work(iterations: int) -> float:
    """Iterate the logistic map ``x <- r x (1 - x)`` ``iterations`` times; return the last x.

    Each step needs the one before: the loop cannot be vectorised, reordered or folded,
    and it touches no memory.
    """
    x = _START
    for _ in range(iterations):
        x = _RATE * x * (1.0 - x)
    return x


def _thread_times(iterations: int, calls: int) -> np.ndarray:
    """Thread CPU time of each of ``calls`` calls of :func:`fixed_work`, s."""
    clock = time.thread_time_ns
    times = np.zeros(max(1, calls))
    for i in range(times.size):
        start = clock()
        fixed_work(iterations)
        times[i] = clock() - start
    return 1e-9 * times


def _call_time(iterations: int, calls: int = 21) -> float:
    """Median thread CPU time of ``calls`` calls of :func:`fixed_work`, s."""
    return float(np.median(_thread_times(iterations, calls)))


def calibrate(target: float = TARGET_CALL_TIME) -> int:
    """Return the iteration count whose call takes about ``target`` s of thread CPU time."""
    fixed_work(1)  # compiled, or loaded from the cache, before anything is timed
    iterations = 1000
    while _call_time(iterations) < 0.25 * target:
        iterations *= 4
    return max(1, round(iterations * target / _call_time(iterations)))


def noise_floor(calls: int, target: float = TARGET_CALL_TIME) -> dict[str, Any]:
    """Time :func:`fixed_work`, sized to ``target`` s, ``calls`` times in thread CPU time.

    Args:
        calls: Timed calls (the replay's tick count: the same sample size as its p99).
        target: Thread CPU time of one call, s.

    Returns:
        ``iterations`` (of the map per call), ``cpu_us`` (:func:`statistics` of the calls'
        thread CPU times, µs) and ``p99_over_median``.
    """
    iterations = calibrate(target)
    cpu = statistics(_thread_times(iterations, calls))
    return {
        'iterations': iterations,
        'cpu_us': cpu,
        'p99_over_median': cpu['p99'] / cpu['median'] if cpu['median'] else None,
    }
