"""``safety_filter_node``: the grasp safety filter as a ROS 2 node (rclpy shell).

Run: ``ros2 run grasp_safety_filter safety_filter_node --ros-args --params-file
config/paper_scenario.yaml``, remapping the topics to a real hand's driver and planner::

    -r /hand/joint_states:=/my_hand/joint_states -r /object/odom:=/object_tracker/odom
    -r /hand/effort_nominal:=/my_planner/effort -r /hand/effort_command:=/my_hand/effort

Subscribes to ``/hand/joint_states``, ``/object/odom`` (or ``/object/pose``,
``input.object_message: pose``) and ``/hand/effort_nominal``; publishes
``/hand/effort_command`` (u*), with ``command.message: float64_multi_array`` also
``/effort_controller/commands`` (u* for ros2_control's JointGroupEffortController),
``/safety_filter/margins`` and ``/diagnostics``. Everything else is
:class:`grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint`. Input stamps are
checked against the node's clock: with the simulator, run it with ``use_sim_time:=true``;
with a real hand, the driver's stamps must be on the same clock as this node, and
``input.sync: latest`` makes a tick of each joint state (with ``latest``, the joint states
and the object's pose are subscribed best effort, which matches any publisher).

Input watchdog: a timer on the steady clock (every
:data:`~grasp_safety_filter.nodes.input_watchdog.WATCHDOG_PERIOD` s; under ``use_sim_time`` a
dead simulator stops the node clock too) calls ``SafetyFilterEndpoint.watchdog``: once no
tick has been accepted for ``input.hold_timeout`` s of wall-clock time, the hold policy's
fallback goes to ``/hand/effort_command`` every period, stamped with the node clock's now
(not before the last tick's stamp), with an ERROR status on ``/diagnostics``. A lockstep
simulator that waits for that stamp applies the fallback and steps. Wall-clock times are
``time.monotonic()``, the same clock as the steady timer's.

Grasp check: until a received state passes the start-up grasp check, and while a contact's
gap or penetration is above ``grasp_check.gap_tolerance``, the filter sends the hold
policy's command instead of solving (``SafetyFilterEndpoint``); each change is logged once
(ERROR when the grasp is not valid, naming the contacts; INFO when it is), not at every
ERROR status.

Live parameters: ``enabled`` (false passes u_nom through; switching is logged, WARN when
off, INFO when on, and the status stays WARN while off), the constraint switches,
``no_slip.normal_force_margin``, the class-K functions, the relaxation weights, the OSQP
settings (these rebuild the filter), ``input.*`` (the hold policy),
``grasp_check.gap_tolerance``, ``diagnostics.period`` and ``margins.period`` (how often the
status and margins of steady ticks go out) apply from the next tick;
``no_slip.pyramid_faces`` and the model are read-only (read at start-up).
"""

from __future__ import annotations

from collections.abc import Mapping
import time
from typing import Any

from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.io.schemas import SAFETY_FILTER_NODE
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_COMMAND,
    EFFORT_NOMINAL,
    JOINT_STATES,
    MARGINS,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.command_output import CommandConfig
from grasp_safety_filter.nodes.controller_node import ControllerNode
from grasp_safety_filter.nodes.grasp_watch import GraspCheckConfig
from grasp_safety_filter.nodes.input_watchdog import WATCHDOG_PERIOD
from grasp_safety_filter.nodes.object_stream import StreamConfig
from grasp_safety_filter.nodes.publication_rate import (
    PUBLICATION_RATE_PARAMETERS,
    PublicationRateConfig,
)
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from grasp_safety_filter.nodes.spin_node import spin_node
from grasp_safety_filter.nodes.tick_kernels import load_filter_kernels

#: Parameter switching the filter off (u* = u_nom) for the paper's unfiltered run.
ENABLED_PARAMETER = 'enabled'


class SafetyFilterNode(ControllerNode):
    """The safety filter node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            SAFETY_FILTER_NODE,
            publishes=(EFFORT_COMMAND, MARGINS, DIAGNOSTICS),
            **kwargs,
        )
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        stream = StreamConfig.from_parameters(self.parameters)
        command_config = CommandConfig.from_parameters(self.parameters)
        topics = stream.topics(EFFORT_NOMINAL)
        self.endpoint = SafetyFilterEndpoint(
            model,
            SafetyFilterConfig.from_parameters(self.parameters),
            InputPolicyConfig.from_parameters(self.parameters),
            self.msgs,
            enabled=self.parameters[ENABLED_PARAMETER],
            publication_rate_config=PublicationRateConfig.from_parameters(self.parameters),
            grasp_check_config=GraspCheckConfig.from_parameters(self.parameters),
            wall_clock=time.monotonic,
            stream=stream,
            command_config=command_config,
            topic_names=self.resolved_topics(topics),
        )
        # Its first tick then costs what the others cost (tick_kernels).
        load_filter_kernels(
            self.parameters, self.config_directory, self.endpoint.filter.config, self.msgs
        )
        for topic in self.endpoint.command.topics:
            if topic != EFFORT_COMMAND:
                self.add_publisher(topic)
        endpoint = self.endpoint
        self.subscribe_input(JOINT_STATES, endpoint.on_joint_states, newest_only=stream.latest)
        self.subscribe_input(stream.object_topic, endpoint.on_odom, sensor=stream.latest)
        self.subscribe_input(EFFORT_NOMINAL, endpoint.on_effort_nominal)
        self.start_watchdog(WATCHDOG_PERIOD)
        state = 'on' if endpoint.enabled else 'OFF (u* = u_nom)'
        self.get_logger().info(
            f'safety filter {state}: {len(endpoint.filter.row_names)} constraint rows'
        )

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Rebuild the filter, update the hold policy or switch the filter on or off (logged)."""
        input_changed = any(name.startswith('input.') for name in changed)
        rate_changed = any(name in PUBLICATION_RATE_PARAMETERS for name in changed)
        grasp_changed = any(name.startswith('grasp_check.') for name in changed)
        filter_changed = any(
            not name.startswith(('input.', 'grasp_check.'))
            and name not in PUBLICATION_RATE_PARAMETERS
            and name != ENABLED_PARAMETER
            for name in changed
        )
        self.endpoint.update_config(
            filter_config=(
                SafetyFilterConfig.from_parameters(self.parameters) if filter_changed else None
            ),
            input_policy_config=(
                InputPolicyConfig.from_parameters(self.parameters) if input_changed else None
            ),
            publication_rate_config=(
                PublicationRateConfig.from_parameters(self.parameters) if rate_changed else None
            ),
            grasp_check_config=(
                GraspCheckConfig.from_parameters(self.parameters) if grasp_changed else None
            ),
        )
        if ENABLED_PARAMETER in changed:
            switched = self.endpoint.switch(
                self.parameters[ENABLED_PARAMETER], now=self.now_seconds()
            )
            # One call site per severity: rclpy refuses to change it between calls.
            if switched is not None and self.endpoint.enabled:
                self.get_logger().info(switched)
            elif switched is not None:
                self.get_logger().warning(switched)


def main(args: list[str] | None = None) -> None:
    """Run ``safety_filter_node`` until Ctrl-C or shutdown."""
    spin_node(SafetyFilterNode, args)


if __name__ == '__main__':
    main()
