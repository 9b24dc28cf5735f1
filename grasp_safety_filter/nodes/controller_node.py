"""What the two controller nodes share: inputs on the node clock and the steady clock.

The nominal controller and the safety filter hand each input to their endpoint with the
node clock's time (``now``, s: simulation time under ``use_sim_time``) and the steady
clock's at receipt (``wall``, s: ``time.monotonic``), publish its answer and log its new
lines (the grasp check's changes, once each; the start-up advice). A timer on the steady
clock calls the endpoint's ``watchdog(wall, now=...)`` and publishes what it returns:
under ``use_sim_time`` a dead or never-started simulator stops the node clock too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
import time
from typing import Any

from rclpy.clock import Clock, ClockType

from grasp_safety_filter.nodes.base_node import EndpointNode
from grasp_safety_filter.nodes.outgoing import Outgoing

#: An endpoint's input handler: ``handler(msg, now=..., wall=...)`` -> messages to send.
InputHandler = Callable[..., list[Outgoing]]


class ControllerNode(EndpointNode):
    """An endpoint node of a controller (module docstring).

    Attributes:
        endpoint: The controller's endpoint (``take_log``, ``watchdog``), set by the subclass.

    """

    endpoint: Any

    def resolved_topics(self, topics: Mapping[str, str]) -> dict[str, str]:
        """Return the topics' names as this node resolves them (remapped), by table name."""
        return {key: self.resolve_topic_name(name) for key, name in topics.items()}

    def subscribe_input(self, topic: str, handler: InputHandler, **qos: bool) -> None:
        """Subscribe ``handler`` to ``topic`` (``qos``: :meth:`subscribe`'s); send its answer."""
        now_seconds, monotonic, answer = self.now_seconds, time.monotonic, self.answer
        self.subscribe(
            topic, lambda msg: answer(handler(msg, now=now_seconds(), wall=monotonic())), **qos
        )

    def start_watchdog(self, period: float) -> None:
        """Call the endpoint's watchdog every ``period`` s of the steady clock; send its answer."""
        endpoint, monotonic = self.endpoint, time.monotonic
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._watchdog_timer = self.create_timer(
            period,
            lambda: self.publish(endpoint.watchdog(monotonic(), now=self.now_seconds())),
            clock=self._steady_clock,
        )

    def answer(self, outgoing: list[Outgoing]) -> None:
        """Publish an input's answer; log the endpoint's new lines."""
        self.publish(outgoing)
        self.log_lines(self.endpoint.take_log())
