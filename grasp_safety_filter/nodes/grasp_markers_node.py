"""``grasp_markers_node``: the grasp as RViz/Foxglove markers (rclpy shell).

Run: ``ros2 run grasp_safety_filter grasp_markers_node --ros-args --params-file
config/paper_scenario.yaml`` (the model section is the controllers'; ``use_sim_time`` as
theirs).

Takes the newest ``/hand/joint_states``, ``/object/odom`` and ``/hand/contacts`` (the
simulator's forces) when it draws (best effort, history one: they match any publisher, and a
1 kHz driver does not wake the node), subscribes to ``/diagnostics`` (the filter's active
rows); publishes ``/grasp/markers`` (``visualization_msgs/MarkerArray``, palm frame) at most
``markers.rate`` times a second of steady time. Set the viewer's fixed frame to the palm
frame (``model.palm_frame``): no TF is needed. The markers are built as rosbags messages and
published serialised (rclpy's message classes would cost most of the node's CPU). Everything
else is :class:`~grasp_safety_filter.nodes.grasp_markers.GraspMarkersEndpoint`.

Live parameters: ``markers.rate`` and ``markers.force_scale``; the model is read-only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rclpy.clock import Clock, ClockType
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.schemas import GRASP_MARKERS_NODE
from grasp_safety_filter.io.topics import (
    CONTACTS,
    DIAGNOSTICS,
    JOINT_STATES,
    MARKERS,
    OBJECT_ODOM,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.base_node import EndpointNode
from grasp_safety_filter.nodes.grasp_markers import GraspMarkersEndpoint, MarkerConfig
from grasp_safety_filter.nodes.spin_node import spin_node, wait_set_executor

#: Shortest interval between two WARN logs of input that did not parse, s.
REJECTION_LOG_PERIOD = 5.0


class GraspMarkersNode(EndpointNode):
    """The grasp-markers node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(GRASP_MARKERS_NODE, publishes=(MARKERS,), **kwargs)
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self.endpoint = GraspMarkersEndpoint(
            model,
            MessageNamespace.from_typestore(self._typestore),
            MarkerConfig.from_parameters(self.parameters),
        )
        self._serialised: tuple[Any, bytes] | None = None  # the last array, serialised
        endpoint = self.endpoint
        self._streams = [
            (self.subscribe_polled(JOINT_STATES), endpoint.on_joint_states),
            (self.subscribe_polled(OBJECT_ODOM), endpoint.on_odom),
            (self.subscribe_polled(CONTACTS), endpoint.on_contacts),
        ]
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
        for subscription, keep in self._streams:
            msg = subscription.take_newest()
            if msg is not None:
                keep(msg)
        markers = self.endpoint.markers()
        if markers is not None:
            if self._serialised is None or self._serialised[0] is not markers:
                data = self._typestore.serialize_cdr(markers, markers.__msgtype__)
                self._serialised = (markers, data.tobytes())
            self.publisher(MARKERS).publish(self._serialised[1])
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
    spin_node(GraspMarkersNode, args, wait_set_executor)


if __name__ == '__main__':
    main()
