"""The analysis reads what the filter writes: every status counted, from a bag."""

from __future__ import annotations

from collections import Counter, deque
import dataclasses
from pathlib import Path

import numpy as np
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.control.safety_filter import FilterStatus
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder, read_bag
from grasp_safety_filter.runner import build_endpoints, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
STEPS = 30
DT = 0.001


class FailingFilter:
    """Wraps a SafetyFilter; its answers on the given calls carry a failed QP status."""

    def __init__(self, core, failures: dict[int, FilterStatus]):
        self.core = core
        self.failures = failures
        self.calls = 0

    def solve(self, state, u_nom):
        self.calls += 1
        result = self.core.solve(state, u_nom)
        failure = self.failures.get(self.calls)
        return result if failure is None else dataclasses.replace(result, status=failure)

    def __getattr__(self, name):
        return getattr(self.core, name)


def corrupt(msg):
    """Make a joint state the filter must reject (a NaN position)."""
    msg.position = np.r_[np.nan, msg.position[1:]]
    return msg


def wall_clock(msg) -> float:
    """Return a steady clock that advances with the run: the message's stamp, s."""
    return m.header_stamp_ns(msg) * 1e-9


def record_faulty_run(bag_path: Path) -> None:
    """Record a lockstep run whose filter meets failed QPs, bad input and missing input.

    Wired as the runner wires the endpoints, except that the filter receives a corrupt
    joint state at t_0 (nothing accepted yet: fallback) and at t_10..t_12 (held), its QP
    "fails" on its 5th and 6th solve, and its watchdog finds no input twice after t_20.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msgs = m.MessageNamespace.from_typestore(typestore)
    sim, nominal, safety_filter = build_endpoints(
        RunOptions(CONFIG, 'filtered', duration=STEPS * DT), msgs
    )
    safety_filter.filter = FailingFilter(
        safety_filter.filter,
        {5: FilterStatus.FALLBACK_NOMINAL, 6: FilterStatus.FALLBACK_LAST_GOOD},
    )
    corrupt_steps = {0, 10, 11, 12}
    watchdog_step = 20

    def filter_joint_states(msg):
        step = round(wall_clock(msg) / DT)
        outgoing = safety_filter.on_joint_states(
            corrupt(msg) if step in corrupt_steps else msg, wall=wall_clock(msg)
        )
        if step == watchdog_step:
            # The steady clock jumps past the hold timeout with nothing more received;
            # the node clock stands at the last tick (the simulator takes no such command).
            late = wall_clock(msg) + safety_filter.hold.hold_timeout
            for k in (1, 2):
                outgoing += safety_filter.watchdog(late + k * 0.02, now=(step - 1) * DT)
        return outgoing

    def filter_input(handler):
        return lambda msg: handler(msg, wall=wall_clock(msg))

    subscribers = {
        topics.JOINT_STATES: [nominal.on_joint_states, filter_joint_states],
        topics.OBJECT_ODOM: [nominal.on_odom, filter_input(safety_filter.on_odom)],
        topics.EFFORT_NOMINAL: [filter_input(safety_filter.on_effort_nominal)],
        topics.EFFORT_COMMAND: [sim.on_command],
    }
    with BagRecorder(bag_path, typestore=typestore) as bag:
        queue = deque(sim.start())
        while queue:
            topic, stamp_ns, msg = queue.popleft()
            data = bag.write(topic, stamp_ns, msg)
            for handler in subscribers.get(topic, []):
                queue.extend(handler(typestore.deserialize_cdr(data, msg.__msgtype__)))
    assert sim.finished and sim.stop_reason == 'duration'


def test_summary_counts_failed_rejected_and_watchdog_ticks_from_the_bag(tmp_path):
    bag = tmp_path / 'bag'
    record_faulty_run(bag)
    run_data = load_run(bag)
    summary = summarize(run_data)
    counts = summary['filter']
    # One status per tick stamp, t_0..t_N; the watchdog's are counted apart.
    assert counts['steps'] == STEPS + 1
    assert counts['failed_steps'] == 2
    assert counts['rejected_steps'] == 4
    assert counts['watchdog_fallbacks'] == 2
    statuses = counts['statuses']
    assert statuses['fallback_nominal'] == 1
    assert statuses['fallback_last_good'] == 1
    assert statuses['input_fallback'] == 1  # t_0: no safe command to hold yet
    assert statuses['input_held'] == 3
    assert sum(statuses.values()) == counts['steps']
    assert Counter(v['status'] for v in run_data.watchdog_values) == {'input_fallback': 2}
    assert summary['mode'] == 'filtered'
    # The watchdog's fallbacks carry the last tick's stamp: the tick's own command is kept.
    stamp = round(0.019e9)
    sent = [
        m.effort_from_msg(msg, run_data.joint_names).effort
        for _, msg in read_bag(bag, topics=[topics.EFFORT_COMMAND])[topics.EFFORT_COMMAND]
        if m.header_stamp_ns(msg) == stamp
    ]
    assert len(sent) == 3 and not np.allclose(sent[0], sent[-1])
    (k,) = np.flatnonzero(np.round(run_data.t_command * 1e9) == stamp)
    np.testing.assert_array_equal(run_data.u_command[k], sent[0])
