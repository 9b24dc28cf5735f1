"""A long run holds no more native memory than a short one: the lockstep loop does not grow.

Python objects are seen by ``tracemalloc``; memory that a C++ extension (pinocchio, OSQP)
allocates and never frees is not. glibc's ``mallinfo2`` counts every byte in use on the
C heap, so growth per tick is measured there.
"""

from __future__ import annotations

from collections import deque
import ctypes
import ctypes.util
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.model.quaternion import from_rotation_matrix
from grasp_safety_filter.runner import build_endpoints, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            'arena',
            'ordblks',
            'smblks',
            'hblks',
            'hblkhd',
            'usmblks',
            'fsmblks',
            'uordblks',
            'fordblks',
            'keepcost',
        )
    ]


def _libc_in_use():
    """Return a function giving glibc's heap bytes in use (skips where there is none)."""
    name = ctypes.util.find_library('c')
    libc = ctypes.CDLL(name) if name else None
    if libc is None or not hasattr(libc, 'mallinfo2'):
        pytest.skip('needs glibc >= 2.33 (mallinfo2) to count native heap bytes')
    libc.mallinfo2.restype = _MallInfo2

    def in_use() -> int:
        info = libc.mallinfo2()
        return info.uordblks + info.hblkhd

    return in_use


@pytest.mark.parametrize(
    'to_quaternion',
    [m.quaternion_xyzw_from_matrix, from_rotation_matrix],
    ids=lambda f: f.__name__,
)
def test_rotation_to_quaternion_frees_what_it_allocates(to_quaternion):
    in_use = _libc_in_use()
    # A C-ordered rotation, as every state and reference message carries.
    R = m.matrix_from_quaternion_xyzw(np.array([0.1, 0.2, 0.3, 0.9]))
    assert R.flags['C_CONTIGUOUS']
    for _ in range(500):
        to_quaternion(R)
    calls = 20_000
    before = in_use()
    for _ in range(calls):
        to_quaternion(R)
    # One leaked copy of R would be 72 bytes a call.
    assert (in_use() - before) / calls < 8.0


def test_the_lockstep_loop_does_not_grow_with_the_run():
    """Native heap growth per tick of the three endpoints in lockstep, over 1000 ticks."""
    in_use = _libc_in_use()
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msgs = m.MessageNamespace.from_typestore(typestore)
    warmup, ticks, every = 200, 1000, 100
    duration = (warmup + ticks + 10) * 0.001
    sim, nominal, safety_filter = build_endpoints(
        RunOptions(CONFIG, 'filtered', duration=duration), msgs
    )
    # Wired as the runner wires them, every message through CDR.
    subscribers = {
        topics.JOINT_STATES: [nominal.on_joint_states, safety_filter.on_joint_states],
        topics.OBJECT_ODOM: [nominal.on_odom, safety_filter.on_odom],
        topics.EFFORT_NOMINAL: [safety_filter.on_effort_nominal],
        topics.EFFORT_COMMAND: [sim.on_command],
    }
    samples: list[tuple[int, int]] = []
    queue = deque(sim.start())
    tick = 0
    while queue:
        topic, _, msg = queue.popleft()
        data = typestore.serialize_cdr(msg, msg.__msgtype__)
        for handler in subscribers.get(topic, []):
            queue.extend(handler(typestore.deserialize_cdr(data, msg.__msgtype__)))
        if topic == topics.JOINT_STATES:
            tick += 1
            if tick >= warmup and (tick - warmup) % every == 0:
                samples.append((tick, in_use()))
            if tick >= warmup + ticks:
                break
    x, y = np.array(samples, dtype=float).T
    slope = np.polyfit(x, y, 1)[0]
    # Before: +80 B/tick (the simulator's odometry quaternion, see the test above).
    assert slope < 16.0, f'native heap grows by {slope:.1f} B/tick'
