"""A real hand's input streams, in one process: a driver, a tracker, the two controllers.

:func:`run_streams` drives a plant (our rigid model, or MuJoCo) as a hand driver does: every
``period`` it publishes the joint states stamped with the wall clock (integer ns, today's
epoch), optionally with joints of an arm first; a tracker captures the object's pose every
``tracker_period`` with Gaussian noise and delivers it ``latency`` later, stamped with its
capture time. The nominal controller and the safety filter endpoints (``input.sync:
latest``) get every message through CDR in the order it arrives; the filter's u* is applied
to the plant from the next period on (zero-order hold, as a driver does). Before the first
command the plant stands still (a real grasp starts with its forces built up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import heapq
from typing import Any

import numpy as np
import pinocchio as pin
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.nodes.outgoing import Outgoing

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = m.MessageNamespace.from_typestore(TYPESTORE)

#: A wall-clock origin of today's epoch, ns: a float in s resolves it to about 0.24 us only.
EPOCH_NS = 1_764_900_000_123_456_789


def through_cdr(msg: Any) -> Any:
    """Serialise to CDR and back, as the middleware does."""
    return TYPESTORE.deserialize_cdr(
        TYPESTORE.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__
    )


@dataclass(frozen=True)
class Streams:
    """The hand's streams.

    Attributes:
        period: Joint-state period of the driver, s (a whole number of plant steps).
        tracker_period: Tracker period, s.
        latency: Tracker latency: capture to delivery, s.
        position_noise: Tracker position noise, standard deviation per axis, m.
        orientation_noise: Tracker orientation noise, standard deviation per axis, rad.
        extra_joints: Joints of an arm, published before the hand's (as a
            ``joint_state_broadcaster`` of an arm with a hand does).
        pose_message: The tracker publishes ``PoseStamped`` (else ``Odometry``).
        seed: Of the tracker's noise.

    """

    period: float = 0.002
    tracker_period: float = 0.01
    latency: float = 0.01
    position_noise: float = 0.0005
    orientation_noise: float = 0.005
    extra_joints: tuple[str, ...] = ()
    pose_message: bool = False
    seed: int = 0


@dataclass
class StreamRun:
    """What a run of :func:`run_streams` produced.

    Attributes:
        states: Joint-state stamps published, ns.
        commands: ``/hand/effort_command`` messages of the filter, in order.
        nominal: ``/hand/effort_nominal`` messages, in order.
        statuses: ``(name, DiagnosticReport)`` of every status, in order.
        stop_reason: The plant's stop reason (None: ran to the end).
        outgoing: Everything the controllers sent.

    """

    states: list[int] = field(default_factory=list)
    commands: list[Any] = field(default_factory=list)
    nominal: list[Any] = field(default_factory=list)
    statuses: list[Any] = field(default_factory=list)
    stop_reason: str | None = None
    outgoing: list[Outgoing] = field(default_factory=list)

    def tick_statuses(self) -> list[str]:
        """Return the ``status`` value of each ``safety_filter`` status, in order."""
        return [
            report.values.get('status', '')
            for report in self.statuses
            if report.name == 'safety_filter'
        ]


def _tracker_message(
    model: Any, streams: Streams, stamp: int, observation: Any, rng: np.random.Generator
) -> Any:
    p = observation.p_object_in_palm + rng.normal(0.0, streams.position_noise, 3)
    R = pin.exp3(rng.normal(0.0, streams.orientation_noise, 3)) @ observation.R_object_to_palm
    if streams.pose_message:
        return m.pose_stamped_to_msg(MSGS, stamp, p, R, frame_id=model.palm_frame)
    return m.odometry_to_msg(
        MSGS,
        stamp,
        p,
        R,
        observation.twist_object,
        frame_id=model.palm_frame,
        child_frame_id=model.object_frame,
    )


def run_streams(
    plant: Any,
    nominal: Any,
    safety_filter: Any,
    streams: Streams,
    duration: float,
    tamper: Callable[[str, Any, int], Any] | None = None,
) -> StreamRun:
    """Drive ``plant`` with the two endpoints over the hand's streams (module docstring).

    Args:
        plant: A plant at its initial grasp (``observe``, ``step``, ``stop_reason``).
        nominal: The nominal controller endpoint.
        safety_filter: The safety filter endpoint.
        streams: The driver's and the tracker's streams.
        duration: Wall time of the run, s.
        tamper: Called with each topic, message and period index before delivery; returns
            the message to deliver, or None to drop it.

    """
    model = nominal.model
    names = list(streams.extra_joints) + list(model.joint_names)
    extra = len(streams.extra_joints)
    period_ns = round(streams.period * 1e9)
    substeps = round(streams.period / plant.time_step)
    assert abs(substeps * plant.time_step - streams.period) < 1e-12
    tracker_every = round(streams.tracker_period / streams.period)
    latency_ns = round(streams.latency * 1e9)
    rng = np.random.default_rng(streams.seed)
    arrivals: list[tuple[int, int, str, Any]] = []
    run = StreamRun()
    u: np.ndarray | None = None
    order = 0

    def deliver(topic: str, msg: Any, now: int, k: int) -> list[Outgoing]:
        if tamper is not None:
            msg = tamper(topic, msg, k)
            if msg is None:
                return []
        msg = through_cdr(msg)
        now_s = now / 1e9
        if topic == topics.JOINT_STATES:
            answers = safety_filter.on_joint_states(msg, now=now_s)
            answers += nominal.on_joint_states(msg, now=now_s)
        elif topic in (topics.OBJECT_ODOM, topics.OBJECT_POSE):
            answers = safety_filter.on_odom(msg, now=now_s) + nominal.on_odom(msg, now=now_s)
        else:
            answers = safety_filter.on_effort_nominal(msg, now=now_s)
        sent = []
        for outgoing in answers:
            sent.append(outgoing)
            if outgoing.topic == topics.EFFORT_NOMINAL:
                sent += deliver(topics.EFFORT_NOMINAL, outgoing.msg, now, k)
        return sent

    for k in range(round(duration / streams.period)):
        now = EPOCH_NS + k * period_ns
        observation = plant.observe()
        if k % tracker_every == 0:
            msg = _tracker_message(model, streams, now, observation, rng)
            topic = topics.OBJECT_POSE if streams.pose_message else topics.OBJECT_ODOM
            heapq.heappush(arrivals, (now + latency_ns, order, topic, msg))
            order += 1
        while arrivals and arrivals[0][0] <= now:
            _, _, topic, msg = heapq.heappop(arrivals)
            run.outgoing += deliver(topic, msg, now, k)
        position = np.r_[np.linspace(-0.3, 0.3, extra), observation.q]
        velocity = np.r_[np.zeros(extra), observation.dq]
        state = m.joint_state_to_msg(MSGS, now, names, position, velocity, None)
        run.states.append(now)
        sent = deliver(topics.JOINT_STATES, state, now, k)
        run.outgoing += sent
        for outgoing in sent:
            if outgoing.topic == topics.EFFORT_COMMAND:
                u = m.effort_from_msg(outgoing.msg, model.joint_names).effort
        if u is not None:
            for _ in range(substeps):
                plant.step(u)
                if plant.stop_reason is not None:
                    break
        if plant.stop_reason is not None:
            run.stop_reason = plant.stop_reason
            break
    for outgoing in run.outgoing:
        if outgoing.topic == topics.EFFORT_COMMAND:
            run.commands.append(outgoing.msg)
        elif outgoing.topic == topics.EFFORT_NOMINAL:
            run.nominal.append(outgoing.msg)
        elif outgoing.topic == topics.DIAGNOSTICS:
            run.statuses += m.diagnostics_from_msg(through_cdr(outgoing.msg)).reports
    return run
