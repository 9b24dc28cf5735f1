"""The object's state at each tick of a hand's joint-state stream (``input.sync: latest``).

A real hand's inputs never share a stamp: the driver publishes joint states at its own rate,
the tracker the object's pose at a lower rate, stamped with its capture time and delivered
late, with noise. :class:`ObjectStream` gives both controllers the object's state at the
stamp of each joint state: the tracker's samples (``nav_msgs/Odometry`` on ``/object/odom``
or ``geometry_msgs/PoseStamped`` on ``/object/pose``, ``input.object_message``) go to an
:class:`~grasp_safety_filter.estimation.object_state.ObjectStateEstimator`, which carries
the pose between them with the hand's own measurement of the object's motion under the
grasp (``G^T x_o_dot = J_h dq``) and corrects it with each sample at its capture time.
:meth:`ObjectStream.grasp_state` returns the model terms at a joint state and that estimate,
and hands them back to the estimator (its next step uses their ``J_h`` and ``G``).

A tick is refused (the hold policy then answers it) before the first tracker sample, and
when the newest sample was captured more than ``object_state.max_age`` before the tick.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.estimation.object_state import (
    ObjectEstimate,
    ObjectEstimateConfig,
    ObjectStateEstimator,
    TrackerSample,
)
from grasp_safety_filter.io.messages import (
    FutureStampError,
    JointStateData,
    MessageError,
    ObjectStateData,
    odometry_from_msg,
    OutOfOrderError,
    pose_stamped_from_msg,
    StaleInputError,
)
from grasp_safety_filter.io.parameters import flatten_parameters
from grasp_safety_filter.io.schemas import (
    EXACT_SYNC,
    LATEST_SYNC,
    ODOMETRY_MESSAGE,
    POSE_MESSAGE,
    STREAM_PARAMETERS,
)
from grasp_safety_filter.io.topics import JOINT_STATES, OBJECT_ODOM, OBJECT_POSE
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.shared_parse import parse_directly, SharedParse
from grasp_safety_filter.nodes.tick_state import model_state

_DEFAULTS = {spec.name: spec.default for spec in STREAM_PARAMETERS}


@dataclass(frozen=True)
class StreamConfig:
    """How a controller makes its ticks from its inputs (``input.sync``, ``object_state.*``).

    Attributes:
        sync: ``exact`` or ``latest`` (:mod:`grasp_safety_filter.io.schemas.inputs`).
        object_message: ``odometry`` or ``pose``.
        correction_time: Time constant of the tracker's correction, s.
        object_max_age: Oldest admissible newest tracker sample at a tick, s.

    """

    sync: str = str(_DEFAULTS['input.sync'])
    object_message: str = str(_DEFAULTS['input.object_message'])
    correction_time: float = float(_DEFAULTS['object_state.correction_time'])
    object_max_age: float = float(_DEFAULTS['object_state.max_age'])

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> StreamConfig:
        """Build from a controller's parameters (missing ones: their defaults)."""
        flat = {**_DEFAULTS, **flatten_parameters(params)}
        return cls(
            str(flat['input.sync']),
            str(flat['input.object_message']),
            float(flat['object_state.correction_time']),
            float(flat['object_state.max_age']),
        )

    @property
    def latest(self) -> bool:
        """Whether each joint state is a tick (``latest``), not each stamp (``exact``)."""
        return self.sync == LATEST_SYNC

    @property
    def object_topic(self) -> str:
        """The topic of the object's pose: ``/object/odom`` or ``/object/pose``."""
        return OBJECT_POSE if self.object_message == POSE_MESSAGE else OBJECT_ODOM

    def topics(self, *others: str) -> dict[str, str]:
        """Return the input topics by table name: the state's (:attr:`object_topic`), others."""
        return {JOINT_STATES: JOINT_STATES, OBJECT_ODOM: self.object_topic} | {
            topic: topic for topic in others
        }

    def estimate_config(self) -> ObjectEstimateConfig:
        """Return the estimator's configuration."""
        return ObjectEstimateConfig(
            correction_time=self.correction_time, max_age=self.object_max_age
        )


#: The exact policy of the lockstep graph: the default of every endpoint.
EXACT = StreamConfig(sync=EXACT_SYNC, object_message=ODOMETRY_MESSAGE)


class ObjectStream:
    """The object's state at the hand's joint states (module docstring).

    Args:
        model: The ``GraspModel`` (frames, ``state(...)``).
        config: The stream configuration (``latest``).
        source: The object topic's name as the node resolved it, for the error texts.
        parse: The odometry parse, shared in process; default: its own.

    Attributes:
        estimator: The object-state estimator.
        last_estimate: The estimate of the last :meth:`grasp_state` (None before).

    """

    def __init__(
        self,
        model: Any,
        config: StreamConfig,
        source: str,
        parse: SharedParse | None = None,
    ) -> None:
        self.model = model
        self.config = config
        self.source = source
        self.estimator = ObjectStateEstimator(config.estimate_config())
        self.last_estimate: ObjectEstimate | None = None
        self._parse = parse_directly if parse is None else parse

    def parse(self, msg: Any) -> ObjectStateData:
        """Parse a tracker message (the configured type; palm and object frames).

        Raises:
            MessageError: As the message's parser.

        """
        if self.config.object_message == POSE_MESSAGE:
            return pose_stamped_from_msg(msg, self.model.palm_frame, self.source)
        frames = (self.model.palm_frame, self.model.object_frame)
        return self._parse(odometry_from_msg, msg, *frames, self.source)

    def add(self, sample: ObjectStateData, now_ns: int | None) -> None:
        """Hand a tracker sample to the estimator.

        Args:
            sample: The parsed sample (stamp: its capture time).
            now_ns: The node's clock, integer ns; None: no clock (no age checks).

        Raises:
            StaleInputError: Captured more than ``object_state.max_age`` before ``now_ns``.
            FutureStampError: Stamped more than that after ``now_ns``.
            OutOfOrderError: Older than the last sample.

        """
        max_age_ns = round(self.config.object_max_age * 1e9)
        if now_ns is not None and sample.stamp_ns < now_ns - max_age_ns:
            raise StaleInputError(
                f'{self.source}: stale stamp {sample.t:.9f} s (captured '
                f'{(now_ns - sample.stamp_ns) / 1e9:.6f} s ago > object_state.max_age '
                f'{self.config.object_max_age} s)'
            )
        if now_ns is not None and sample.stamp_ns > now_ns + max_age_ns:
            raise FutureStampError(
                f'{self.source}: future stamp {sample.t:.9f} s (ahead of the node clock by '
                f'{(sample.stamp_ns - now_ns) / 1e9:.6f} s > object_state.max_age)'
            )
        tracked = TrackerSample(
            sample.stamp_ns, sample.p_object_in_palm, sample.R_object_to_palm, sample.twist_object
        )
        if not self.estimator.add_tracker_sample(tracked):
            raise OutOfOrderError(
                f'{self.source}: out-of-order stamp {sample.t:.9f} s, older than the last sample'
            )

    def estimate(self, joints: JointStateData) -> ObjectEstimate:
        """Return the object's estimate at a joint state's stamp.

        Raises:
            MessageError: No tracker sample yet.
            StaleInputError: The newest sample is older than ``object_state.max_age``.

        """
        estimate = self.estimator.estimate(joints.stamp_ns, joints.velocity)
        if estimate is None:
            raise MessageError(f'{self.source}: no object pose received yet')
        if estimate.tracker_age > self.config.object_max_age:
            raise StaleInputError(
                f'{self.source}: the newest object pose is {estimate.tracker_age:.3f} s old at '
                f't = {joints.t:.9f} s (object_state.max_age {self.config.object_max_age} s)'
            )
        return estimate

    def grasp_state(self, joints: JointStateData) -> GraspState:
        """Return the model terms at a joint state and the object's estimate at its stamp.

        Raises:
            MessageError: As :meth:`estimate`.
            ValueError: The model refuses the state (``np.linalg.LinAlgError`` too).

        """
        estimate = self.estimate(joints)
        state = model_state(self.model, joints, estimate)
        self.estimator.observe(state)
        self.last_estimate = estimate
        return state

    @staticmethod
    def object_data(joints: JointStateData, state: GraspState) -> ObjectStateData:
        """Return the estimate a tick used, as the object input of its ``TickInputs``."""
        return ObjectStateData(
            t=joints.t,
            stamp_ns=joints.stamp_ns,
            p_object_in_palm=state.p_object_in_palm,
            R_object_to_palm=state.R_object_to_palm,
            twist_object=np.asarray(state.twist_object),
        )
