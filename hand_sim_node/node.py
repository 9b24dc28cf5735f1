"""``hand_sim_node``: the hand–object simulator as a ROS 2 node (rclpy shell).

Run: ``ros2 run grasp_safety_filter hand_sim_node --ros-args --params-file
config/paper_scenario.yaml -p use_sim_time:=true``.

Publishes ``/grasp/scenario`` (once, latched), ``/clock``, ``/hand/joint_states``,
``/object/odom``, ``/hand/contacts`` and ``/diagnostics``; subscribes to
``/hand/effort_command``. Everything else is :class:`hand_sim_node.endpoint.HandSimEndpoint`.

Start-up: the initial grasp is checked (:mod:`grasp_safety_filter.model.grasp_check`:
joint limits, every fingertip on its face within ``GAP_TOLERANCE``); a bad one stops the
node with one line naming the joint or contact. The run starts (scenario and state at t_0
published) once the controllers are connected
(:func:`hand_sim_node.start_up.start_blockers`: a node publishing the command, it and the
nodes it reads from subscribed to the state) and, with
``start.wait_for_recorder`` set to a recorder's node name (``rosbag2_recorder`` for
``ros2 bag record``), once that recorder is subscribed to every published topic of the topic
table, so that neither the controllers nor the bag miss the first tick; the graph must stay
so for ``START_SETTLE`` s (``RECORDER_SETTLE`` s with a recorder). While it waits it logs
what it waits for every ``WAITING_LOG_PERIOD`` s. Then in lockstep (the default) each
command stamped with the current state's stamp advances the simulation by one step, as fast
as the controllers answer. A wall-clock watchdog reports a command missing for
``command_timeout`` s and publishes the state again. Without lockstep, a wall-clock timer
steps every ``time_step`` s with the latest command. The node exits one second after the run
ends (so that a launch file with ``on_exit=Shutdown()`` ends the demo and a recorder closes
its bag).

Live parameters: ``stop_on_slip``, ``stop_on_workspace_exit``,
``stabilization.position_gain``, ``stabilization.velocity_gain`` and ``command_timeout``
apply from the next step; the others are read-only (read at start-up).
"""

from __future__ import annotations

from collections.abc import Mapping
import time
from typing import Any

import rclpy
from rclpy.clock import Clock, ClockType

from grasp_safety_filter.io.schemas import HAND_SIM_NODE
from grasp_safety_filter.io.topics import (
    CLOCK,
    CONTACTS,
    DIAGNOSTICS,
    EFFORT_COMMAND,
    JOINT_STATES,
    OBJECT_ODOM,
    SCENARIO,
    TOPICS,
)
from grasp_safety_filter.model.grasp_check import check_initial_grasp
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.base_node import EndpointNode, spin_node
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.plant import PlantConfig
from hand_sim_node.start_up import GraphSnapshot, load_step_kernels, start_blockers

#: Wall-clock period of the start-up and watchdog checks, s.
CHECK_PERIOD = 0.05

#: Wall-clock delay between the end of the run and the node's exit, s.
EXIT_DELAY = 1.0

#: Wall-clock period of the log line saying what the start waits for, s.
WAITING_LOG_PERIOD = 2.0

#: Wall-clock time the graph must stay connected before the run starts, s. The simulator
#: sees its own discovery only: the other nodes' participants may take longer to discover
#: each other, and a reliable, volatile writer drops what it publishes before it has matched
#: a reader. Between the controllers the lockstep watchdog recovers a lost first command.
START_SETTLE = 1.0

#: The same with a recorder to wait for, s: what it misses is lost for the bag. A pair of
#: participants that missed each other's initial announcements meets at the next periodic
#: one (Fast DDS announces every 3 s).
RECORDER_SETTLE = 3.5

#: Parameter naming the recorder node to wait for (empty: none).
RECORDER_PARAMETER = 'start.wait_for_recorder'


class HandSimNode(EndpointNode):
    """The simulator node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            HAND_SIM_NODE,
            publishes=(SCENARIO, CLOCK, JOINT_STATES, OBJECT_ODOM, CONTACTS, DIAGNOSTICS),
            **kwargs,
        )
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        check_initial_grasp(model, self.parameters)
        self.endpoint = HandSimEndpoint(
            model,
            SimConfig.from_parameters(self.parameters),
            self.msgs,
            plant_config=PlantConfig.from_parameters(self.parameters),
        )
        load_step_kernels(self.endpoint)  # before the check timer can start the run
        self._command_subscription = self.subscribe(EFFORT_COMMAND, self._on_command)
        # Timers on the steady clock: simulation time stands still while the simulator waits.
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._check_timer = self.create_timer(CHECK_PERIOD, self._check, clock=self._steady_clock)
        self._step_timer = None
        if not self.endpoint.lockstep:
            self._step_timer = self.create_timer(
                self.endpoint.config.time_step, self._advance, clock=self._steady_clock
            )
        self._exit_timer = None
        self._waiting_logged_at = time.monotonic()
        self._connected_since: float | None = None
        self.recorder = str(self.parameters[RECORDER_PARAMETER])
        recorder = f" and recorder '{self.recorder}'" if self.recorder else ''
        self.get_logger().info(
            f'simulating {model.n_joints} joints, {model.n_contacts} contacts on the '
            f'{self.endpoint.plant_config.kind} plant for '
            f'{self.endpoint.config.duration} s in steps of {self.endpoint.config.time_step} s '
            f'({"lockstep" if self.endpoint.lockstep else "free-running"}); waiting for a '
            f'controller on {self._command_subscription.topic_name}{recorder}'
        )

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Apply new stop rules, stabilisation gains or command timeout."""
        self.endpoint.update_config(SimConfig.from_parameters(self.parameters))

    # ------------------------------------------------------------------------ callbacks
    def _on_command(self, msg: Any) -> None:
        self.publish(self.endpoint.on_command(msg, now=time.monotonic()))
        self._exit_if_finished()

    def _advance(self) -> None:
        self.publish(self.endpoint.advance())
        self._exit_if_finished()

    def _check(self) -> None:
        now = time.monotonic()
        if self.endpoint.started:
            self.publish(self.endpoint.timeout(now))
            return
        blockers = start_blockers(self._graph_snapshot(), self.recorder)
        if not blockers:
            if self._connected_since is None:
                self._connected_since = now
            if now - self._connected_since < (RECORDER_SETTLE if self.recorder else START_SETTLE):
                return
            recorder = f" and recorder '{self.recorder}'" if self.recorder else ''
            self.get_logger().info(f'controllers{recorder} connected: starting the run')
            self.publish(self.endpoint.start(now=now))
            return
        self._connected_since = None
        if now - self._waiting_logged_at >= WAITING_LOG_PERIOD:
            self._waiting_logged_at = now
            self.get_logger().info(f'waiting to start the run for {"; ".join(blockers)}')

    def _graph_snapshot(self) -> GraphSnapshot:
        """Return the topic table's publishers and subscribers as this node sees them."""
        me = self.get_fully_qualified_name()

        def nodes(infos: list[Any]) -> frozenset[str]:
            names = (f'{i.node_namespace.rstrip("/")}/{i.node_name}' for i in infos)
            return frozenset(name for name in names if name != me)

        return GraphSnapshot(
            publishers={s.name: nodes(self.get_publishers_info_by_topic(s.name)) for s in TOPICS},
            subscribers={
                s.name: nodes(self.get_subscriptions_info_by_topic(s.name)) for s in TOPICS
            },
            matched={
                topic: self.publisher(topic).get_subscription_count()
                for topic in (JOINT_STATES, OBJECT_ODOM)
            },
        )

    def _exit_if_finished(self) -> None:
        if self.endpoint.finished and self._exit_timer is None:
            self.get_logger().info(
                f'run finished at t = {self.endpoint.t:.3f} s ({self.endpoint.stop_reason}); '
                f'exiting in {EXIT_DELAY} s'
            )
            self._check_timer.cancel()
            if self._step_timer is not None:
                self._step_timer.cancel()
            self._exit_timer = self.create_timer(EXIT_DELAY, self._exit, clock=self._steady_clock)

    def _exit(self) -> None:
        self._exit_timer.cancel()
        rclpy.try_shutdown(context=self.context)


def main(args: list[str] | None = None) -> None:
    """Run ``hand_sim_node`` until the run ends, Ctrl-C or shutdown."""
    spin_node(HandSimNode, args)


if __name__ == '__main__':
    main()
