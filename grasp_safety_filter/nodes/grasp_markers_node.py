"""``grasp_markers_node``: the grasp as RViz/Foxglove markers (rclpy shell).

Run: ``ros2 run grasp_safety_filter grasp_markers_node --ros-args --params-file
config/paper_scenario.yaml`` (the model section is the controllers'; ``use_sim_time`` as
theirs).

Subscribes to ``/hand/joint_states`` and ``/object/odom`` (newest only, best effort: they
match any publisher; kept serialised, the newest converted when drawn), ``/hand/contacts``
(the simulator's forces) and ``/diagnostics`` (the filter's active rows); publishes
``/grasp/markers`` (``visualization_msgs/MarkerArray``, palm frame) at most ``markers.rate``
times a second of steady time. Set the viewer's fixed frame to the palm frame
(``model.palm_frame``): no TF is needed. Everything else is
:class:`~grasp_safety_filter.nodes.grasp_markers.GraspMarkersEndpoint`.

Live parameters: ``markers.rate`` and ``markers.force_scale``; the model is read-only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.serialization import deserialize_message

from grasp_safety_filter.io.messages import rclpy_message_class
from grasp_safety_filter.io.schemas import GRASP_MARKERS_NODE
from grasp_safety_filter.io.topics import (
    CONTACTS,
    DIAGNOSTICS,
    JOINT_STATES,
    MARKERS,
    OBJECT_ODOM,
    topic_spec,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.base_node import EndpointNode
from grasp_safety_filter.nodes.grasp_markers import GraspMarkersEndpoint, MarkerConfig
from grasp_safety_filter.nodes.spin_node import spin_node

#: Shortest interval between two WARN logs of input that did not parse, s.
REJECTION_LOG_PERIOD = 5.0


class GraspMarkersNode(EndpointNode):
    """The grasp-markers node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(GRASP_MARKERS_NODE, publishes=(MARKERS,), **kwargs)
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        self.endpoint = GraspMarkersEndpoint(
            model, self.msgs, MarkerConfig.from_parameters(self.parameters)
        )
        endpoint = self.endpoint
        # The streams are kept serialised and only the newest is converted, when drawn: a
        # 1 kHz driver then costs this node a reference per message, not a message object.
        self._streams = {
            JOINT_STATES: endpoint.on_joint_states,
            OBJECT_ODOM: endpoint.on_odom,
            CONTACTS: endpoint.on_contacts,
        }
        self._newest: dict[str, bytes] = {}
        self._classes = {t: rclpy_message_class(topic_spec(t).msgtype) for t in self._streams}
        for topic in self._streams:
            self.subscribe(
                topic,
                lambda data, topic=topic: self._newest.__setitem__(topic, data),
                newest_only=True,
                raw=True,
            )
        self.subscribe(DIAGNOSTICS, endpoint.on_diagnostics)
        # Steady time: markers keep coming when a simulator's clock stops, as a viewer expects.
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = None
        self._start_timer()
        self.get_logger().info(
            f'grasp markers on {self.resolve_topic_name(MARKERS)}, frame {model.palm_frame!r}, '
            f'at most {endpoint.config.rate:g} Hz'
        )

    def _start_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._timer = self.create_timer(
            1.0 / self.endpoint.config.rate, self._publish_markers, clock=self._steady_clock
        )

    def _publish_markers(self) -> None:
        for topic, handle in self._streams.items():
            data = self._newest.pop(topic, None)
            if data is not None:
                handle(deserialize_message(data, self._classes[topic]))
        markers = self.endpoint.markers()
        if markers is not None:
            self.publisher(MARKERS).publish(markers)
        if self.endpoint.last_error is not None:
            self.get_logger().warning(
                self.endpoint.last_error, throttle_duration_sec=REJECTION_LOG_PERIOD
            )
            self.endpoint.last_error = None

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Apply a new rate or force scale."""
        self.endpoint.config = MarkerConfig.from_parameters(self.parameters)
        if 'markers.rate' in changed:
            self._start_timer()


def main(args: list[str] | None = None) -> None:
    """Run ``grasp_markers_node`` until Ctrl-C or shutdown."""
    spin_node(GraspMarkersNode, args)


if __name__ == '__main__':
    main()
