"""``nominal_controller_node``: the paper's nominal controller as a ROS 2 node (rclpy shell).

Run: ``ros2 run grasp_safety_filter nominal_controller_node --ros-args --params-file
config/paper_scenario.yaml -p use_sim_time:=true``.

Subscribes to ``/hand/joint_states``, ``/object/odom`` (or ``/object/pose``,
``input.object_message: pose``) and, with ``reference.source: topic``,
``/object/reference`` (a planner's ``trajectory_msgs/MultiDOFJointTrajectory`` of
the joint ``object``, palm frame); publishes ``/hand/effort_nominal``,
``/object/reference_sample`` (each tick's reference sample, for the analysis) and
``/diagnostics``.
Everything else is
:class:`grasp_safety_filter.nodes.nominal_controller.NominalControllerEndpoint`. With
``input.sync: latest`` every joint state is a tick and the joint states and the object's
pose are subscribed best effort (which matches any publisher). Before its first tick it
says every second what it waits for (WARN on ``/diagnostics``, logged).

Live parameters: ``gains.kp``, ``gains.kd``, ``gains.kf``, ``null_space.kp``,
``null_space.kd``, ``reference.amplitude``, ``reference.frequency`` and
``reference.timeout`` and ``grasp_check.gap_tolerance`` apply from the next tick (the
null-space posture is kept);
``reference.source`` and the model are read-only (read at start-up).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from grasp_safety_filter.control.nominal import NominalConfig
from grasp_safety_filter.io.schemas import NOMINAL_CONTROLLER_NODE
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_NOMINAL,
    JOINT_STATES,
    OBJECT_REFERENCE,
    OBJECT_REFERENCE_SAMPLE,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.controller_node import ControllerNode
from grasp_safety_filter.nodes.grasp_watch import GAP_TOLERANCE_PARAMETER, GraspCheckConfig
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.object_stream import StreamConfig
from grasp_safety_filter.nodes.spin_node import spin_node
from grasp_safety_filter.nodes.tick_kernels import load_nominal_kernels

#: Steady-clock period of the check whether a "waiting for a first tick" report is due, s.
WAITING_CHECK_PERIOD = 0.1


class NominalControllerNode(ControllerNode):
    """The nominal controller node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            NOMINAL_CONTROLLER_NODE,
            publishes=(EFFORT_NOMINAL, OBJECT_REFERENCE_SAMPLE, DIAGNOSTICS),
            **kwargs,
        )
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        config = NominalConfig.from_parameters(self.parameters)
        stream = StreamConfig.from_parameters(self.parameters)
        topics = stream.topics()
        self.endpoint = NominalControllerEndpoint(
            model,
            config,
            self.msgs,
            GraspCheckConfig.from_parameters(self.parameters),
            stream=stream,
            topic_names=self.resolved_topics(topics),
        )
        # Its first tick then costs what the others cost (tick_kernels).
        load_nominal_kernels(self.parameters, self.config_directory, config, self.msgs)
        endpoint = self.endpoint
        self.subscribe_input(JOINT_STATES, endpoint.on_joint_states, newest_only=stream.latest)
        self.subscribe_input(stream.object_topic, endpoint.on_odom, sensor=stream.latest)
        # Before its first tick it says every second what it waits for.
        self.start_watchdog(WAITING_CHECK_PERIOD)
        if config.reference_source == 'topic':
            self.subscribe(
                OBJECT_REFERENCE, lambda msg: self.publish(self.endpoint.on_reference(msg))
            )
        self.get_logger().info(f'nominal controller ready, reference: {config.reference_source}')

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Apply new gains, paper reference shape, topic reference timeout or gap tolerance."""
        self.endpoint.update_config(
            NominalConfig.from_parameters(self.parameters),
            GraspCheckConfig.from_parameters(self.parameters)
            if GAP_TOLERANCE_PARAMETER in changed
            else None,
        )


def main(args: list[str] | None = None) -> None:
    """Run ``nominal_controller_node`` until Ctrl-C or shutdown."""
    spin_node(NominalControllerNode, args)


if __name__ == '__main__':
    main()
