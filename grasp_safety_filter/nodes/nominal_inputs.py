"""The nominal controller's ticks from its inputs: the state of each tick, or why there is none.

- ``input.sync: exact`` (the lockstep simulator): a tick is a joint state and an object
  odometry of one stamp; unpaired inputs wait (at most :data:`MAX_PENDING` each).
- ``input.sync: latest`` (a real hand): each joint state is a tick, the object's state the
  estimate at its stamp (:class:`~grasp_safety_filter.nodes.object_stream.ObjectStream`);
  the tracker's samples go to the estimator.

:class:`NominalInputs` parses each message (joints by name, those the model does not have
ignored) and answers with a :class:`Tick` (the stamp and the model terms), a
:class:`Rejection` (the error, and the stamp of the input it belongs to when it has one) or
nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from grasp_safety_filter.io.messages import (
    joint_state_from_msg,
    JointStateData,
    MessageError,
    ObjectStateData,
    odometry_from_msg,
    seconds_to_nanoseconds,
)
from grasp_safety_filter.io.topics import JOINT_STATES, OBJECT_ODOM
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.object_stream import ObjectStream, StreamConfig
from grasp_safety_filter.nodes.shared_parse import parse_directly, SharedParse
from grasp_safety_filter.nodes.tick_state import model_state

#: Unpaired inputs kept waiting for their partner (older ones are dropped).
MAX_PENDING = 64


class Tick(NamedTuple):
    """A tick's stamp (integer ns) and model terms."""

    stamp: int
    state: GraspState


class Rejection(NamedTuple):
    """An input that makes no tick: why, and its stamp (ns) if it has a usable one."""

    error: Exception
    stamp: int | None


class NominalInputs:
    """The nominal controller's ticks (module docstring).

    Args:
        model: The ``GraspModel``.
        stream: ``input.sync`` and the object's estimate.
        topic_names: The input topics as the node resolved them, by table name.
        parse: The joint state and odometry parses, shared in process; default: its own.

    """

    def __init__(
        self,
        model: Any,
        stream: StreamConfig,
        topic_names: Mapping[str, str],
        parse: SharedParse | None = None,
    ) -> None:
        self.model = model
        self.topic_names = dict(topic_names)
        self._parse = parse_directly if parse is None else parse
        self._joint_name_tuple = tuple(model.joint_names)
        self.objects = (
            ObjectStream(model, stream, self.topic_names[OBJECT_ODOM], parse)
            if stream.latest
            else None
        )
        self._joint_states: dict[int, JointStateData] = {}
        self._odometry: dict[int, ObjectStateData] = {}

    def joint_states(self, msg: Any) -> Tick | Rejection | None:
        """Take a joint state: a tick (``latest``; ``exact`` once its odometry is in)."""
        source = self.topic_names[JOINT_STATES]
        try:
            data = self._parse(joint_state_from_msg, msg, self._joint_name_tuple, source, True)
        except MessageError as error:
            return Rejection(error, None)
        if self.objects is None:
            self._joint_states[data.stamp_ns] = data
            return self._pair(data.stamp_ns)
        try:
            return Tick(data.stamp_ns, self.objects.grasp_state(data))
        except (ValueError, np.linalg.LinAlgError) as error:  # MessageError is a ValueError
            return Rejection(error, data.stamp_ns)

    def object_pose(self, msg: Any, now: float | None) -> Tick | Rejection | None:
        """Take the object's pose: a tracker sample (``latest``), or a tick's odometry.

        ``now``: the node's clock, s, against which a tracker sample's age is checked.
        """
        if self.objects is not None:
            try:
                sample = self.objects.parse(msg)
                now_ns = None if now is None else seconds_to_nanoseconds(max(now, 0.0))
                self.objects.add(sample, now_ns)
            except MessageError as error:
                return Rejection(error, None)
            return None
        try:
            frames = (self.model.palm_frame, self.model.object_frame)
            data = self._parse(odometry_from_msg, msg, *frames, self.topic_names[OBJECT_ODOM])
        except MessageError as error:
            return Rejection(error, None)
        self._odometry[data.stamp_ns] = data
        return self._pair(data.stamp_ns)

    def _pair(self, stamp: int) -> Tick | Rejection | None:
        """Return the tick of ``stamp`` once its joint state and odometry are both in."""
        if stamp not in self._joint_states or stamp not in self._odometry:
            for pending in (self._joint_states, self._odometry):
                while len(pending) > MAX_PENDING:
                    del pending[min(pending)]
            return None
        joints = self._joint_states.pop(stamp)
        odometry = self._odometry.pop(stamp)
        # Anything older than this tick can no longer be paired in order.
        for pending in (self._joint_states, self._odometry):
            for old in [s for s in pending if s < stamp]:
                del pending[old]
        try:
            state = model_state(self.model, joints, odometry)
        except (ValueError, np.linalg.LinAlgError) as error:
            return Rejection(error, stamp)
        return Tick(stamp, state)
