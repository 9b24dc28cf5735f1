r"""One closed-loop run's joint speeds, corrections and relaxed ticks, as one JSON line.

The tables of docs/qp_metric.md and docs/class_k_gains.md (the example hand) come from
this script: the runner's lockstep wiring of the three endpoints (as ``grasp-demo``), with
no bag, and the filter's status of every tick::

    PYTHONPATH=. python test/closed_loop_study.py config/four_finger_box.yaml filtered 10 \\
        gains.kf=2.0 qp.metric=inverse_inertia

Arguments: the scenario file, ``filtered`` or ``nominal``, the simulated duration (s), then
any parameters as ``NAME=VALUE`` (numbers are read as floats). Printed: the largest and the
median over the run of ``max_j |dq_j|`` (rad/s, every ``/hand/joint_states``), the largest
``|u* - u_nom|`` (N·m), the relaxed ticks (relaxed or fallback), and ``held``: the run
reached its duration with no slip, separation, joint-limit or workspace violation.
"""

from __future__ import annotations

from collections import deque
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.runner import _subscribers, build_endpoints, RunOptions

_RELAXED = {FilterStatus.RELAXED, FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL}


def run(config: Path, mode: str, duration: float, overrides: dict[str, Any]) -> dict[str, Any]:
    """Run the scenario in lockstep and return the run's figures."""
    msgs = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
    options = RunOptions(config, mode=mode, duration=duration, overrides=overrides)
    sim, nominal, safety_filter = build_endpoints(options, msgs)
    subscribers = _subscribers(sim, nominal, safety_filter)
    statuses: list[FilterStatus] = []
    filter_ = safety_filter.filter
    solve = filter_.solve

    def recording_solve(state: Any, u_nom: np.ndarray) -> Any:
        result = solve(state, u_nom)
        statuses.append(result.status)
        return result

    filter_.solve = recording_solve
    speeds: list[float] = []
    u_nominal: dict[int, np.ndarray] = {}
    u_command: dict[int, np.ndarray] = {}
    queue = deque(sim.start())
    while queue:
        topic, stamp_ns, msg = queue.popleft()
        if topic == topics.JOINT_STATES:
            speeds.append(float(np.abs(np.asarray(msg.velocity)).max()))
        elif topic == topics.EFFORT_NOMINAL:
            u_nominal[stamp_ns] = np.asarray(msg.effort, dtype=float)
        elif topic == topics.EFFORT_COMMAND:
            u_command[stamp_ns] = np.asarray(msg.effort, dtype=float)
        for handler in subscribers.get(topic, ()):
            queue.extend(handler(msg))
    simulator = sim.simulator
    violations = {name: record.count for name, record in simulator.log.families.items()}
    corrections = [np.abs(u - u_nominal[t]).max() for t, u in u_command.items() if t in u_nominal]
    return {
        'config': str(config),
        'mode': mode,
        'overrides': overrides,
        't_end': simulator.t,
        'held': abs(simulator.t - duration) < 1e-9 and not any(violations.values()),
        'violations': violations,
        'max_joint_speed': max(speeds),
        'median_joint_speed': float(np.median(speeds)),
        'max_correction': float(max(corrections, default=0.0)),
        'relaxed_ticks': sum(status in _RELAXED for status in statuses),
        'ticks': len(statuses),
    }


def main(argv: list[str]) -> int:
    """Parse ``CONFIG MODE DURATION [NAME=VALUE ...]``, run, print one JSON line."""
    config, mode, duration, *assignments = argv
    overrides: dict[str, Any] = {}
    for assignment in assignments:
        name, value = assignment.split('=', 1)
        try:
            overrides[name] = float(value)
        except ValueError:
            overrides[name] = value
    print(json.dumps(run(Path(config), mode, float(duration), overrides)), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
