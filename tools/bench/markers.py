"""The marker node's CPU: ``python -m grasp_tools.bench.markers [--config F] [--driver HZ]``.

Starts ``grasp_markers_node`` with a scenario file and feeds it, from this process, the
simulator's first state as a driver would: joint states at ``--driver`` Hz and the object's
odometry at 100 Hz, stamped with the clock. After a warm-up it prints the markers received
per second and the node's CPU (user + system, from ``/proc``) as a share of one core, the
figure ``markers.rate`` trades against. Set your own ``ROS_DOMAIN_ID``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint


def _cpu_seconds(pid: int) -> float:
    """Return a process's user + system CPU time, s (Linux ``/proc``)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def main(argv: list[str] | None = None) -> int:
    """Measure and print the marker node's rate and CPU (module docstring)."""
    parser = argparse.ArgumentParser(prog='python -m grasp_tools.bench.markers')
    parser.add_argument('--config', type=Path, default=config_path(), help='scenario file')
    parser.add_argument('--driver', type=float, default=500.0, help='joint states per s')
    parser.add_argument('--rate', type=float, default=30.0, help='markers.rate, Hz')
    parser.add_argument('--duration', type=float, default=10.0, help='measured s (after 5 s)')
    args = parser.parse_args(argv)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    params = load_node_parameters(args.config, HAND_SIM_NODE)
    model = GraspModel.from_parameters(params, args.config.parent)
    rosbags_msgs = m.MessageNamespace.from_typestore()
    start = {o.topic: o.msg for o in HandSimEndpoint(
        model, SimConfig.from_parameters(params), rosbags_msgs).start()}  # fmt: skip
    joints = m.joint_state_from_msg(start[topics.JOINT_STATES], model.joint_names)
    pose = m.odometry_from_msg(start[topics.OBJECT_ODOM], model.palm_frame, model.object_frame)
    command = [
        str(Path(sys.executable).parent / 'grasp_markers_node'), '--ros-args',
        '--params-file', str(args.config), '-p', f'markers.rate:={args.rate}',
    ]  # fmt: skip
    node_process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node('markers_bench')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    msgs = m.MessageNamespace.from_rclpy()

    def spec(topic: str) -> tuple[type, object]:
        table = topics.topic_spec(topic)
        return m.rclpy_message_class(table.msgtype), table.qos.to_rclpy()

    received = [0]
    node.create_subscription(
        *spec(topics.MARKERS)[:1], topics.MARKERS,
        lambda _: received.__setitem__(0, received[0] + 1), spec(topics.MARKERS)[1],
    )  # fmt: skip
    state_publisher = node.create_publisher(*spec(topics.JOINT_STATES)[:1], topics.JOINT_STATES,
                                            spec(topics.JOINT_STATES)[1])  # fmt: skip
    odom_publisher = node.create_publisher(*spec(topics.OBJECT_ODOM)[:1], topics.OBJECT_ODOM,
                                           spec(topics.OBJECT_ODOM)[1])  # fmt: skip
    odom_every = max(1, round(args.driver / 100.0))

    def drive(seconds: float) -> None:
        due, k = time.monotonic(), 0
        end = due + seconds
        while due < end:
            stamp = node.get_clock().now().nanoseconds
            state_publisher.publish(m.joint_state_to_msg(
                msgs, stamp, model.joint_names, joints.position, joints.velocity, None))
            if k % odom_every == 0:
                odom_publisher.publish(m.odometry_to_msg(
                    msgs, stamp, pose.p_object_in_palm, pose.R_object_to_palm,
                    np.asarray(pose.twist_object), frame_id=model.palm_frame,
                    child_frame_id=model.object_frame))  # fmt: skip
            k += 1
            due += 1.0 / args.driver
            while (wait := due - time.monotonic()) > 0.0:
                executor.spin_once(timeout_sec=wait)

    try:
        drive(5.0)
        cpu, wall, count = _cpu_seconds(node_process.pid), time.monotonic(), received[0]
        drive(args.duration)
        elapsed = time.monotonic() - wall
        share = (_cpu_seconds(node_process.pid) - cpu) / elapsed
        rate = (received[0] - count) / elapsed
    finally:
        node_process.terminate()
        node_process.wait(timeout=30)
        rclpy.shutdown()
    print(
        f'grasp_markers_node, {args.config.name}: driver {args.driver:g} Hz, odometry 100 Hz; '
        f'markers {rate:.1f}/s (markers.rate {args.rate:g}); CPU {100 * share:.1f} % of one core'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
