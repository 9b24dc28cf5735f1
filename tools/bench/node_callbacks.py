"""The safety filter node's callbacks per tick, timed in the runner's lockstep run.

The replay times the model terms and the filter step; the node does more in a tick: it
parses its three inputs, checks their stamps, runs the filter, the grasp check and the
margins, and builds its output messages. The ROS-free runner wires the very same endpoint
(:class:`~grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint`); through its
``wrap_filter_callback`` (:func:`grasp_safety_filter.runner.record_run`) each of the
endpoint's three callbacks is timed in thread CPU time, and a tick's times are summed by
the stamp of its inputs.

In the runner the nominal controller, called first, parses ``/hand/joint_states`` and
``/object/odom`` and the filter reuses that parse
(:mod:`~grasp_safety_filter.nodes.shared_parse`): a ROS node parses them itself.
"""

from __future__ import annotations

import time
from typing import Any, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the runner (bag, analysis) is imported when a run is timed, not before
    from grasp_safety_filter.runner import Callback

#: The endpoint's subscriber callbacks: one call of each makes a tick.
CALLBACKS_PER_TICK = 3


class FilterCallbackTimes:
    """Thread CPU time of the filter endpoint's callbacks, summed per input stamp."""

    def __init__(self) -> None:
        # stamp (ns) -> [callbacks seen, thread CPU time (ns)], in order of arrival.
        self._by_stamp: dict[int, list[int]] = {}

    def wrap(self, callback: Callback) -> Callback:
        """Return ``callback`` timed: it gets the message and returns its messages unchanged."""
        clock = time.thread_time_ns
        by_stamp = self._by_stamp

        def timed(msg: Any) -> list[Any]:
            start = clock()
            outgoing = callback(msg)
            elapsed = clock() - start
            stamp = msg.header.stamp
            entry = by_stamp.setdefault(1_000_000_000 * stamp.sec + stamp.nanosec, [0, 0])
            entry[0] += 1
            entry[1] += elapsed
            return outgoing

        return timed

    def per_tick(self) -> np.ndarray:
        """Return the thread CPU time of each tick whose three inputs all arrived, s."""
        return np.array(
            [
                1e-9 * elapsed
                for calls, elapsed in self._by_stamp.values()
                if calls == CALLBACKS_PER_TICK
            ]
        )
