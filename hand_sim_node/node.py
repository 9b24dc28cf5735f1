"""``hand_sim_node``: the hand–object simulator as a ROS 2 node (rclpy shell).

Run: ``ros2 run grasp_safety_filter hand_sim_node --ros-args --params-file
config/paper_scenario.yaml -p use_sim_time:=true``.

Lockstep (``lockstep: true``, the default): publishes ``/grasp/scenario`` (once, latched),
``/clock``, ``/hand/joint_states``, ``/object/odom``, ``/hand/contacts`` and ``/diagnostics``;
subscribes to ``/hand/effort_command``. Everything else is
:class:`hand_sim_node.endpoint.HandSimEndpoint`.

Hardware mode (``lockstep: false``): a hand's driver and an object tracker on the wall clock,
:class:`hand_sim_node.hardware.HardwareEndpoint`. A steady-clock timer at ``hardware.rate``
ticks it; messages are stamped with the node's clock (system time: ``use_sim_time`` must be
false; no ``/clock``). It publishes ``/grasp/scenario``, ``/hand/joint_states``, the
tracker's ``/object/odom`` or ``/object/pose``, ``/object/true_odom``, ``/hand/contacts``
and ``/diagnostics``, and subscribes to ``/hand/effort_command`` or
``/effort_controller/commands`` (``hardware.command_message``). It starts at once, as a
driver does (with ``start.wait_for_recorder``, once the recorder is subscribed); the run
ends ``duration`` s of simulated time after the first command.

Start-up (lockstep): the initial grasp is checked (:mod:`grasp_safety_filter.model.grasp_check`:
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
``command_timeout`` s and publishes the state again. In either mode the node exits one
second after the run ends (so that a launch file with ``on_exit=Shutdown()`` ends the demo
and a recorder closes its bag).

Live parameters: ``stop_on_slip``, ``stop_on_workspace_exit``,
``stabilization.position_gain``, ``stabilization.velocity_gain`` and (lockstep)
``command_timeout`` apply from the next step; the others are read-only (read at start-up).
"""

from __future__ import annotations

from collections.abc import Mapping
import time
from typing import Any

import rclpy
from rclpy.clock import Clock, ClockType

from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import HAND_SIM_NODE
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_COMMAND,
    JOINT_STATES,
    OBJECT_ODOM,
    TOPICS,
)
from grasp_safety_filter.model.grasp_check import check_initial_grasp
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.base_node import EndpointNode
from grasp_safety_filter.nodes.spin_node import spin_node
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.hardware import HardwareEndpoint
from hand_sim_node.hardware_config import HardwareConfig
from hand_sim_node.plant import PlantConfig
from hand_sim_node.start_up import (
    GraphSnapshot,
    load_step_kernels,
    LOCKSTEP_TOPICS,
    start_blockers,
)

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
        super().__init__(HAND_SIM_NODE, publishes=(DIAGNOSTICS,), **kwargs)
        model = GraspModel.from_parameters(self.parameters, self.config_directory)
        check_initial_grasp(model, self.parameters)
        sim_config = SimConfig.from_parameters(self.parameters)
        plant_config = PlantConfig.from_parameters(self.parameters)
        self.endpoint: HandSimEndpoint | HardwareEndpoint
        if sim_config.lockstep:
            self.endpoint = HandSimEndpoint(
                model, sim_config, self.msgs, plant_config=plant_config
            )
            self.published = tuple(sorted(LOCKSTEP_TOPICS))
            command_topic = EFFORT_COMMAND
        else:
            if self.get_parameter('use_sim_time').value:
                raise ParameterError(
                    "parameter 'use_sim_time': the hardware mode (lockstep false) stamps with "
                    'the system clock and publishes no /clock; expected false, got true'
                )
            hardware = HardwareConfig.from_parameters(self.parameters)
            self.endpoint = HardwareEndpoint(
                model, sim_config, hardware, self.msgs, plant_config=plant_config
            )
            self.published = self.endpoint.topics
            command_topic = hardware.command_topic
        for topic in self.published:
            if topic != DIAGNOSTICS:
                self.add_publisher(topic)
        load_step_kernels(self.endpoint)  # before the check timer can start the run
        self._command_subscription = self.subscribe(command_topic, self._on_command)
        # Timers on the steady clock: simulation time stands still while the simulator waits.
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._check_timer = self.create_timer(CHECK_PERIOD, self._check, clock=self._steady_clock)
        self._driver_timer = None
        self._exit_timer = None
        self._waiting_logged_at = time.monotonic()
        self._connected_since: float | None = None
        self.recorder = str(self.parameters[RECORDER_PARAMETER])
        recorder = f" and recorder '{self.recorder}'" if self.recorder else ''
        if isinstance(self.endpoint, HardwareEndpoint):
            tracker = self.endpoint.hardware.tracker
            mode = (
                f'hardware mode: driver at {self.endpoint.hardware.rate:g} Hz '
                f'({self.endpoint.substeps} steps per period), tracker on {tracker.topic} at '
                f'{tracker.rate:g} Hz; commands on {command_topic}'
            )
            waiting = f'; waiting for recorder {self.recorder!r}' if self.recorder else ''
        else:
            mode = 'lockstep'
            waiting = f'; waiting for a controller on {command_topic}{recorder}'
        self.get_logger().info(
            f'simulating {model.n_joints} joints, {model.n_contacts} contacts on the '
            f'{plant_config.kind} plant for {sim_config.duration} s in steps of '
            f'{sim_config.time_step} s ({mode}){waiting}'
        )

    def apply_parameters(self, changed: Mapping[str, Any]) -> None:
        """Apply new stop rules, stabilisation gains or command timeout."""
        self.endpoint.update_config(SimConfig.from_parameters(self.parameters))

    # ------------------------------------------------------------------------ callbacks
    @property
    def hardware(self) -> bool:
        """Whether the node runs the hardware mode (``lockstep: false``)."""
        return isinstance(self.endpoint, HardwareEndpoint)

    def _on_command(self, msg: Any) -> None:
        if isinstance(self.endpoint, HardwareEndpoint):
            now_ns = self._steady_clock.now().nanoseconds
            stamp_ns = self.get_clock().now().nanoseconds
            self.publish(self.endpoint.on_command(msg, now_ns, stamp_ns))
        else:
            self.publish(self.endpoint.on_command(msg, now=time.monotonic()))
        self._exit_if_finished()

    def _tick(self) -> None:
        now_ns = self._steady_clock.now().nanoseconds
        self.publish(self.endpoint.tick(now_ns, self.get_clock().now().nanoseconds))
        self._exit_if_finished()

    def _check(self) -> None:
        now = time.monotonic()
        if self.endpoint.started:
            if not self.hardware:
                self.publish(self.endpoint.timeout(now))
            return
        blockers = start_blockers(
            self._graph_snapshot(), self.recorder, self.published, controllers=not self.hardware
        )
        if not blockers:
            if self._connected_since is None:
                self._connected_since = now
            settle = RECORDER_SETTLE if self.recorder else START_SETTLE
            if self.hardware and not self.recorder:
                settle = 0.0  # a driver waits for nobody
            if now - self._connected_since < settle:
                return
            self._start(now)
            return
        self._connected_since = None
        if now - self._waiting_logged_at >= WAITING_LOG_PERIOD:
            self._waiting_logged_at = now
            self.get_logger().info(f'waiting to start the run for {"; ".join(blockers)}')

    def _start(self, now: float) -> None:
        recorder = f" and recorder '{self.recorder}'" if self.recorder else ''
        if isinstance(self.endpoint, HardwareEndpoint):
            self.get_logger().info(f'hardware mode{recorder}: starting the driver')
            self._check_timer.cancel()
            # The driver's periods start at now_ns; the timer, created just after, fires at
            # them (never before), at exactly the period: rclpy truncates its float period
            # to whole ns, so it is given half a nanosecond more.
            now_ns = self._steady_clock.now().nanoseconds
            period_ns = self.endpoint.period_ns
            self._driver_timer = self.create_timer(
                (period_ns + 0.5) / 1e9, self._tick, clock=self._steady_clock
            )
            if self._driver_timer.timer_period_ns != period_ns:
                self.get_logger().warning(
                    f'driver timer period {self._driver_timer.timer_period_ns} ns, expected '
                    f'{period_ns} ns: periods will be counted late or early'
                )
            self.publish(self.endpoint.start(now_ns, self.get_clock().now().nanoseconds))
            return
        self.get_logger().info(f'controllers{recorder} connected: starting the run')
        self.publish(self.endpoint.start(now=now))

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
                if topic in self.published
            },
        )

    def _exit_if_finished(self) -> None:
        if self.endpoint.finished and self._exit_timer is None:
            self.get_logger().info(
                f'run finished at t = {self.endpoint.t:.3f} s ({self.endpoint.stop_reason}); '
                f'exiting in {EXIT_DELAY} s'
            )
            self._check_timer.cancel()
            if self._driver_timer is not None:
                self._driver_timer.cancel()
            self._exit_timer = self.create_timer(EXIT_DELAY, self._exit, clock=self._steady_clock)

    def _exit(self) -> None:
        self._exit_timer.cancel()
        rclpy.try_shutdown(context=self.context)


def main(args: list[str] | None = None) -> None:
    """Run ``hand_sim_node`` until the run ends, Ctrl-C or shutdown."""
    spin_node(HandSimNode, args)


if __name__ == '__main__':
    main()
