"""The safety filter's input checks: stamps, and the three inputs of one tick put together.

Each input is parsed by joint name (and frame), in model joint order. A tick of stamp t
needs ``/hand/joint_states`` (t), ``/object/odom`` (t) and ``/hand/effort_nominal`` (t).
:class:`TickAssembler` checks each parsed input's stamp (a
:class:`~grasp_safety_filter.io.messages.StampGuard` per topic: stale, future, out of
order; and never a stamp of a tick already closed), keeps incomplete sets (at most
:data:`MAX_PENDING` stamps), computes a set's model terms as soon as its state is complete
(the nominal controller computes u_nom from the same state meanwhile) and hands the set
over when it is complete. A complete set arriving again for the last tick's stamp (a
simulator that re-sent its state) is a replay: the endpoint sends the same answer again.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

from grasp_safety_filter.io.messages import (
    effort_from_msg,
    EffortData,
    header_stamp_ns,
    joint_state_from_msg,
    JointStateData,
    MessageError,
    nanoseconds_to_seconds,
    ObjectStateData,
    odometry_from_msg,
    OutOfOrderError,
    seconds_to_nanoseconds,
    StampGuard,
)
from grasp_safety_filter.io.topics import EFFORT_NOMINAL, JOINT_STATES, OBJECT_ODOM
from grasp_safety_filter.nodes.shared_parse import parse_directly, SharedParse
from grasp_safety_filter.nodes.tick_state import model_state, timed_state, TimedState

#: Incomplete input sets kept waiting for their other inputs (older ones are dropped).
MAX_PENDING = 64

#: The inputs of a tick, and those of its state.
INPUTS = (JOINT_STATES, OBJECT_ODOM, EFFORT_NOMINAL)
STATE_INPUTS = (JOINT_STATES, OBJECT_ODOM)


class TickInputs(NamedTuple):
    """The three validated inputs of one tick (a named tuple: made on every tick).

    Attributes:
        joint_states: Joint positions, velocities and efforts, model joint order.
        odometry: Object pose and twist, palm frame.
        nominal: The nominal torque u_nom, model joint order.

    """

    joint_states: JointStateData
    odometry: ObjectStateData
    nominal: EffortData


#: :meth:`TickAssembler.add`'s answer to the last input of a re-sent tick.
REPLAY = 'replay'


class TickAssembler:
    """Stamp checks and pending inputs of the safety filter (module docstring).

    Args:
        max_age: ``input.max_age``, s.
        model: The ``GraspModel`` whose ``state(...)`` gives a tick's model terms.
        parse: The joint state and odometry parses, shared with the nominal controller in
            process (:mod:`~grasp_safety_filter.nodes.shared_parse`); default: its own.
        topic_names: The input topics' names as the node resolved them (remapped), by table
            name, for the error texts.

    Attributes:
        guard: Stale and out-of-order stamp checks, per input topic.
        last_tick_ns: Stamp of the last closed tick, ns (None before any).

    """

    def __init__(
        self,
        max_age: float,
        model: Any,
        parse: SharedParse | None,
        topic_names: Mapping[str, str],
    ) -> None:
        self.guard = StampGuard(max_age)
        self.topic_names = dict(topic_names)
        self._parse = parse_directly if parse is None else parse
        self.last_tick_ns: int | None = None
        self.model = model
        self._joint_name_tuple = tuple(model.joint_names)
        self._pending: dict[int, dict[str, Any]] = {}
        self._states: dict[int, TimedState] = {}
        self._replay: dict[str, Any] = {}

    def parse(self, topic: str, msg: Any) -> JointStateData | ObjectStateData | EffortData:
        """Parse an input message by joint name (and frame), in model joint order.

        Raises:
            MessageError: The message is not valid (names what and where).

        """
        source = self.topic_names[topic]
        if topic == OBJECT_ODOM:
            frames = (self.model.palm_frame, self.model.object_frame)
            return self._parse(odometry_from_msg, msg, *frames, source)
        if topic == JOINT_STATES:
            return self._parse(joint_state_from_msg, msg, self._joint_name_tuple, source, True)
        return effort_from_msg(msg, self._joint_name_tuple, source)

    def _timed_state(self, joint_states: JointStateData, odometry: ObjectStateData) -> TimedState:
        """Compute a state's model terms (or the model's refusal of it), timed in s."""
        return timed_state(lambda: model_state(self.model, joint_states, odometry))

    def now(self, msg: Any, now: float | None) -> tuple[float, bool]:
        """Return the clock for this input, s, and whether it is one.

        ``now``, else the last tick's time; before any tick and without ``now``, the
        message's own stamp (or 0.0), which is no clock: a rejection then closes no tick.
        """
        if now is not None:
            return float(now), True
        if self.last_tick_ns is not None:
            return nanoseconds_to_seconds(self.last_tick_ns), True
        try:
            return nanoseconds_to_seconds(header_stamp_ns(msg)), False
        except (AttributeError, MessageError):
            return 0.0, False

    def check(self, topic: str, data: Any, now: float) -> int:
        """Return the stamp of a parsed input on ``topic``, integer ns, if it is current.

        Raises:
            MessageError: Stale, future or out of order, or of a tick already closed.

        """
        source = self.topic_names[topic]
        self.guard.accept(source, data.t, now)
        stamp = data.stamp_ns
        if self.last_tick_ns is not None and stamp < self.last_tick_ns:
            raise OutOfOrderError(
                f'{source}: stamp {data.t:.9f} s belongs to a tick already closed (last '
                f'tick {nanoseconds_to_seconds(self.last_tick_ns):.9f} s)'
            )
        return stamp

    def add(self, topic: str, stamp: int, data: Any) -> TickInputs | str | None:
        """Keep a checked input; return its tick's inputs once complete.

        Returns:
            The :class:`TickInputs` of ``stamp`` when this input completes them;
            :data:`REPLAY` when it completes a re-sent set of the last tick; else None.

        """
        if stamp == self.last_tick_ns:
            self._replay[topic] = data
            if len(self._replay) < len(INPUTS):
                return None
            self._replay = {}
            return REPLAY
        inputs = self._pending.setdefault(stamp, {})
        inputs[topic] = data
        if len(inputs) < len(INPUTS):
            if topic in STATE_INPUTS and all(name in inputs for name in STATE_INPUTS):
                # The state is complete before u_nom: the model terms need not wait for it.
                self._states[stamp] = self._timed_state(inputs[JOINT_STATES], inputs[OBJECT_ODOM])
            while len(self._pending) > MAX_PENDING:
                oldest = min(self._pending)
                del self._pending[oldest]
                self._states.pop(oldest, None)
            return None
        del self._pending[stamp]
        return TickInputs(inputs[JOINT_STATES], inputs[OBJECT_ODOM], inputs[EFFORT_NOMINAL])

    def state(self, stamp: int, inputs: TickInputs) -> TimedState:
        """Return the model terms of a complete tick (computed already, or now)."""
        return self._states.pop(stamp, None) or self._timed_state(
            inputs.joint_states, inputs.odometry
        )

    def has_pending(self, stamp: int) -> bool:
        """Whether some but not all inputs of ``stamp`` are in hand."""
        return stamp in self._pending

    def pending_states(self) -> dict[int, TimedState]:
        """Return the model terms computed for incomplete ticks, by stamp (a copy)."""
        return dict(self._states)

    def close(self, stamp: int) -> None:
        """Mark the tick of ``stamp`` as done: drop every older or equal pending input."""
        self.last_tick_ns = stamp
        self._replay = {}
        for old in [s for s in self._pending if s <= stamp]:
            del self._pending[old]
        for old in [s for s in self._states if s <= stamp]:
            del self._states[old]

    def clock_stamp(self, now: float) -> int:
        """Stamp from the node clock ``now`` (s), not before the last tick's stamp, ns."""
        stamp = seconds_to_nanoseconds(max(now, 0.0))
        if self.last_tick_ns is not None:
            stamp = max(stamp, self.last_tick_ns)
        return stamp

    def fallback_stamp(self, now: float) -> int:
        """Stamp of the input watchdog's fallback, ns: :meth:`clock_stamp`, past a pending tick.

        A tick of the clock's stamp under way (a lockstep simulator waits for its command
        while the nominal controller is slow) must not be answered by the fallback in its
        place: the fallback goes 1 ns later, and the tick still gets its own u* when its
        inputs are complete.
        """
        stamp = self.clock_stamp(now)
        return stamp + 1 if self.has_pending(stamp) else stamp

    def dropped(self, topic: str, error: MessageError) -> bool:
        """Whether an input refused by :meth:`parse` or :meth:`check` goes unanswered: never."""
        return False

    def current_stamp(self, msg: Any, now: float) -> int | None:
        """Return the message's stamp if readable, not before the last tick, not in the future.

        "Future" is beyond ``now + input.max_age``: a garbled stamp must not close ticks
        that have not happened yet.
        """
        try:
            stamp = header_stamp_ns(msg)
        except (AttributeError, MessageError):
            return None
        if self.last_tick_ns is not None and stamp < self.last_tick_ns:
            return None
        if nanoseconds_to_seconds(stamp) > now + self.guard.max_age:
            return None
        return stamp
