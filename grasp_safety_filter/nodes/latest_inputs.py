"""The safety filter's ticks on a real hand's streams (``input.sync: latest``).

Each joint state is a tick, stamped as the joint state. Its object state is the estimate at
that stamp (:class:`~grasp_safety_filter.nodes.object_stream.ObjectStream`), computed with
the model terms as soon as the joint state is in. Its u_nom is

- the one stamped as the joint state, when u_nom answers states (the package's nominal
  controller does: it ticks on the same joint states and stamps its answer alike); the tick
  then waits for it, and one that never comes is dropped when a later tick is answered;
- otherwise (a controller of one's own, stamping with its own clock or at its own rate) the
  newest u_nom, if no older than ``input.max_age`` at the tick's stamp.

Which of the two holds is read off the stream: a u_nom stamped as a state in hand makes the
ticks wait for theirs; one that matches no state (stamped no later than the newest state, or
left unmatched when a later state arrives) makes every tick take the newest. The tracker's
samples are checked (stale, future, out of order) and go to the estimator; they make no tick.
A u_nom for a tick already answered, or stale (late), is dropped.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from grasp_safety_filter.io.messages import (
    EffortData,
    FutureStampError,
    JointStateData,
    MessageError,
    nanoseconds_to_seconds,
    OutOfOrderError,
    seconds_to_nanoseconds,
    StaleInputError,
)
from grasp_safety_filter.io.topics import EFFORT_NOMINAL, JOINT_STATES, OBJECT_ODOM
from grasp_safety_filter.nodes.object_stream import ObjectStream, StreamConfig
from grasp_safety_filter.nodes.shared_parse import SharedParse
from grasp_safety_filter.nodes.tick_inputs import TickAssembler, TickInputs
from grasp_safety_filter.nodes.tick_state import timed_state, TimedState

#: States kept waiting for their u_nom, and unmatched u_nom kept for their state (the
#: oldest are dropped beyond this).
MAX_WAITING = 8


class LatestTickAssembler(TickAssembler):
    """The filter's ticks on the joint-state stream (module docstring).

    Args:
        max_age: ``input.max_age``, s: the oldest u_nom (at a tick's stamp) and joint state
            (at the node's clock).
        model: The ``GraspModel``.
        stream: The object's estimate at the joint states.
        topic_names: The input topics as the node resolved them, by table name.

    Attributes:
        nominal_answers: Whether u_nom answers states (stamped as them): ticks wait for it.
        late_nominal: u_nom received for ticks already answered, or stale, dropped.

    """

    def __init__(
        self,
        max_age: float,
        model: Any,
        stream: ObjectStream,
        topic_names: Mapping[str, str],
    ) -> None:
        super().__init__(max_age, model, None, topic_names)
        self.stream = stream
        self.nominal_answers = True
        self.late_nominal = 0
        self._waiting: dict[int, tuple[JointStateData, TimedState]] = {}
        self._unmatched: dict[int, EffortData] = {}
        self._newest_nominal: EffortData | None = None
        self._newest_state_ns: int | None = None
        self._ready: dict[int, TimedState] = {}

    def parse(self, topic: str, msg: Any) -> Any:
        """Parse an input (the object's by the stream's message type)."""
        if topic == OBJECT_ODOM:
            return self.stream.parse(msg)
        return super().parse(topic, msg)

    def check(self, topic: str, data: Any, now: float) -> int:
        """Return the input's stamp, ns, if current; a tracker sample goes to the estimator.

        Raises:
            MessageError: Stale, future or out of order (a joint state: also not after the
                last tick).

        """
        if topic == OBJECT_ODOM:
            self.stream.add(data, seconds_to_nanoseconds(max(now, 0.0)))
            return data.stamp_ns
        if topic == JOINT_STATES:
            return super().check(topic, data, now)
        if self._late(data.stamp_ns):
            return data.stamp_ns  # dropped by add, not refused: nothing is wrong with it
        self.guard.accept(self.topic_names[topic], data.t, now)
        return data.stamp_ns

    def dropped(self, topic: str, error: MessageError) -> bool:
        """Whether a refused input goes unanswered: a stale, future or out-of-order u_nom.

        It is the late answer to a state already gone (the states queued behind a stall
        are still to be answered); counted in :attr:`late_nominal`.
        """
        late = topic == EFFORT_NOMINAL and isinstance(
            error, StaleInputError | OutOfOrderError | FutureStampError
        )
        self.late_nominal += late
        return late

    def _late(self, stamp: int) -> bool:
        """Whether a u_nom answers a tick already answered (when u_nom answers states)."""
        return (
            self.nominal_answers
            and self.last_tick_ns is not None
            and stamp <= self.last_tick_ns
            and stamp not in self._waiting
        )

    def add(self, topic: str, stamp: int, data: Any) -> TickInputs | None:
        """Take a checked input; return a tick's inputs when it is complete.

        Raises:
            MessageError: A joint state with no current object estimate, or no current u_nom
                for it (a controller that does not answer states).

        """
        if topic == JOINT_STATES:
            return self._add_state(stamp, data)
        if topic == EFFORT_NOMINAL:
            return self._add_nominal(stamp, data)
        return None

    def _add_state(self, stamp: int, joints: JointStateData) -> TickInputs | None:
        timed = timed_state(lambda: self.stream.grasp_state(joints))
        self._newest_state_ns = stamp
        if any(s < stamp for s in self._unmatched):
            self.nominal_answers = False  # a u_nom that no state of its stamp came for
            self._unmatched.clear()
        nominal = self._unmatched.pop(stamp, None)
        if nominal is not None:
            self.nominal_answers = True
            return self._ready_tick(joints, timed, nominal)
        if not self.nominal_answers:
            return self._ready_tick(joints, timed, self._current_nominal(joints))
        self._waiting[stamp] = (joints, timed)
        _bound(self._waiting)
        return None

    def _add_nominal(self, stamp: int, nominal: EffortData) -> TickInputs | None:
        waiting = self._waiting.pop(stamp, None)
        if waiting is not None:
            self.nominal_answers = True
            self._newest_nominal = nominal
            return self._ready_tick(*waiting, nominal)
        if self._late(stamp):
            self.late_nominal += 1  # the answer to a tick already answered
            return None
        self._newest_nominal = nominal
        if self._newest_state_ns is None or stamp > self._newest_state_ns:
            self._unmatched[stamp] = nominal  # its state may come yet
            _bound(self._unmatched)
            return None
        # Stamped as no state in hand: a controller with its own stamps.
        self.nominal_answers = False
        if not self._waiting:
            return None
        newest = max(self._waiting)
        joints, timed = self._waiting.pop(newest)
        return self._ready_tick(joints, timed, self._current_nominal(joints))

    def _current_nominal(self, joints: JointStateData) -> EffortData:
        """Return the newest u_nom, if no older than ``input.max_age`` at the state's stamp."""
        source = self.topic_names[EFFORT_NOMINAL]
        nominal = self._newest_nominal
        if nominal is None:
            raise MessageError(f'{source}: no u_nom received yet')
        age = nanoseconds_to_seconds(joints.stamp_ns - nominal.stamp_ns)
        if age > self.guard.max_age:
            raise StaleInputError(
                f'{source}: the newest u_nom (t = {nominal.t:.9f} s) is {age:.6f} s older '
                f'than the state at t = {joints.t:.9f} s (input.max_age {self.guard.max_age} s)'
            )
        return nominal

    def _ready_tick(
        self, joints: JointStateData, timed: TimedState, nominal: EffortData
    ) -> TickInputs:
        self._ready[joints.stamp_ns] = timed
        state = timed[0]
        odometry = (
            None if isinstance(state, Exception) else self.stream.object_data(joints, state)
        )
        return TickInputs(joints, odometry, nominal)  # type: ignore[arg-type]

    def state(self, stamp: int, inputs: TickInputs) -> TimedState:
        """Return the model terms of a tick (computed when its joint state came)."""
        return self._ready.pop(stamp)

    def has_pending(self, stamp: int) -> bool:
        """Whether a state of ``stamp`` waits for its u_nom."""
        return stamp in self._waiting

    def pending_states(self) -> dict[int, TimedState]:
        """Return the model terms of the states waiting for their u_nom, by stamp (a copy)."""
        return {stamp: timed for stamp, (_, timed) in self._waiting.items()}

    def close(self, stamp: int) -> None:
        """Mark the tick of ``stamp`` as answered: drop the older states waiting."""
        if self.last_tick_ns is not None and stamp < self.last_tick_ns:
            return  # the ticks' stamps only go forward
        self.last_tick_ns = stamp
        for old in [s for s in self._waiting if s <= stamp]:
            del self._waiting[old]
        for old in [s for s in self._unmatched if s <= stamp]:
            del self._unmatched[old]
        self._ready.clear()


def tick_assembler(
    stream: StreamConfig,
    max_age: float,
    model: Any,
    parse: SharedParse | None,
    topic_names: Mapping[str, str],
) -> TickAssembler:
    """Return the safety filter's ticks of ``input.sync``: one a stamp, or one a joint state.

    Args:
        stream: ``input.sync`` and the object's estimate.
        max_age: ``input.max_age``, s.
        model: The ``GraspModel``.
        parse: The parses shared in process (``exact`` only; default: its own).
        topic_names: The input topics as the node resolved them, by table name.

    """
    if not stream.latest:
        return TickAssembler(max_age, model, parse, topic_names)
    objects = ObjectStream(model, stream, topic_names[OBJECT_ODOM])
    return LatestTickAssembler(max_age, model, objects, topic_names)


def _bound(pending: dict[int, Any]) -> None:
    """Drop the oldest entries beyond :data:`MAX_WAITING`."""
    while len(pending) > MAX_WAITING:
        del pending[min(pending)]
