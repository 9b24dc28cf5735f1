"""An object tracker emulated on the simulator's states: capture, noise, latency.

A vision or motion-capture tracker sees the object at its own rate, publishes each pose
stamped with its capture time, some tens of milliseconds late, with millimetre noise
(DESIGN.md §9). :class:`TrackerEmulator` does the same with the states the hardware mode's
driver publishes (:mod:`hand_sim_node.hardware`):

- **capture**: sample ``j`` is due once ``j / rate`` s of driver time have passed since the
  start; it is taken at the first driver period at or after that instant, of the plant's
  state there, and stamped with that state's stamp (integer ns). Samples due within one
  timer call (the driver caught up late periods) are taken once, at the call's state;
- **noise**: position ``p + n_p``, ``n_p ~ N(0, position_noise² I₃)`` (palm frame, m);
  orientation ``exp3(n_r) R``, ``n_r ~ N(0, orientation_noise² I₃)`` (rad, palm frame),
  from a generator seeded with ``tracker.seed`` (three position draws, then three
  orientation draws per sample);
- **latency**: a sample is queued and published at the first driver period whose stamp is
  at or after ``capture stamp + latency``.

``tracker.message: odometry`` publishes ``nav_msgs/Odometry`` on ``/object/odom`` with the
true twist (the plant's, in the true object frame, REP 105; a tracker measures no twist,
this is an odometry source's best case); ``pose`` a ``geometry_msgs/PoseStamped`` on
``/object/pose``. Frames: the model's palm frame (pose) and object frame (child).
"""

from __future__ import annotations

from collections import deque
import math
from typing import Any

import numpy as np
import pinocchio as pin

from grasp_safety_filter.io.messages import (
    MessageNamespace,
    NANOSECONDS_PER_SECOND,
    odometry_to_msg,
    pose_stamped_to_msg,
)
from grasp_safety_filter.io.schemas import ODOMETRY_MESSAGE
from grasp_safety_filter.nodes.outgoing import Outgoing
from hand_sim_node.hardware_config import TrackerConfig
from hand_sim_node.simulator import SimState

#: Round-off allowance when a driver time lands exactly on a capture instant.
_CAPTURE_EPSILON = 1e-9


class TrackerEmulator:
    """Samples of the object's pose, noisy and late (module docstring).

    Args:
        config: Rate, latency, noise, message type, seed.
        msgs: Message classes to build (rclpy or rosbags).
        palm_frame: ``header.frame_id`` of the samples.
        object_frame: ``child_frame_id`` of an Odometry sample.

    Attributes:
        captured: Samples taken since the reset.
        published: Samples released since the reset.
        merged: Capture instants that fell within one timer call with another (taken once).
    """

    def __init__(
        self, config: TrackerConfig, msgs: MessageNamespace, palm_frame: str, object_frame: str
    ) -> None:
        self.config = config
        self.msgs = msgs
        self.palm_frame = palm_frame
        self.object_frame = object_frame
        self.reset()

    def reset(self) -> None:
        """Forget the queue and the counts; restart the noise from the seed."""
        self._rng = np.random.default_rng(self.config.seed)
        self._queue: deque[tuple[int, Outgoing]] = deque()
        self._next_index = 0
        self.captured = 0
        self.published = 0
        self.merged = 0

    @property
    def pending(self) -> int:
        """Samples captured and not yet published."""
        return len(self._queue)

    def on_state(self, elapsed_ns: int, stamp_ns: int, state: SimState) -> list[Outgoing]:
        """Take a driver state: capture a sample if one is due, release the samples due.

        Args:
            elapsed_ns: Driver time since the start, integer ns (a whole number of periods).
            stamp_ns: The state's stamp, integer ns (the capture time of a sample taken now).
            state: The plant's state at that stamp.

        Returns:
            The samples whose publication time (capture stamp + latency) is at or before
            ``stamp_ns``, oldest first.
        """
        due = math.floor(elapsed_ns * self.config.rate / NANOSECONDS_PER_SECOND + _CAPTURE_EPSILON)
        if due >= self._next_index:
            self.merged += due - self._next_index
            self._next_index = due + 1
            release_ns = stamp_ns + self.config.latency_ns
            self._queue.append((release_ns, self.sample(stamp_ns, state)))
            self.captured += 1
        return self.release(stamp_ns)

    def release(self, stamp_ns: int) -> list[Outgoing]:
        """Return the queued samples due at ``stamp_ns`` (integer ns), oldest first."""
        out = []
        while self._queue and self._queue[0][0] <= stamp_ns:
            out.append(self._queue.popleft()[1])
        self.published += len(out)
        return out

    def sample(self, stamp_ns: int, state: SimState) -> Outgoing:
        """Return one noisy sample of ``state``'s object pose stamped ``stamp_ns`` (ns)."""
        config = self.config
        p_measured_in_palm = state.p_object_in_palm + self._rng.normal(
            0.0, config.position_noise, 3
        )
        rotation_noise = self._rng.normal(0.0, config.orientation_noise, 3)
        R_measured_to_palm = pin.exp3(rotation_noise) @ state.R_object_to_palm
        msg: Any
        if config.message == ODOMETRY_MESSAGE:
            # The true twist in the true object frame; odometry_to_msg expresses the palm
            # twist it is given in the (measured) pose's frame, so hand it the twist that
            # the measured frame turns back into the true one.
            R_true = state.R_object_to_palm
            twist = state.twist_object
            twist_in_object = np.concatenate((R_true.T @ twist[:3], R_true.T @ twist[3:]))
            twist_for_message = np.concatenate(
                (
                    R_measured_to_palm @ twist_in_object[:3],
                    R_measured_to_palm @ twist_in_object[3:],
                )
            )
            msg = odometry_to_msg(
                self.msgs,
                stamp_ns,
                p_measured_in_palm,
                R_measured_to_palm,
                twist_for_message,
                frame_id=self.palm_frame,
                child_frame_id=self.object_frame,
            )
        else:
            msg = pose_stamped_to_msg(
                self.msgs,
                stamp_ns,
                p_measured_in_palm,
                R_measured_to_palm,
                frame_id=self.palm_frame,
            )
        return Outgoing(config.topic, stamp_ns, msg)
