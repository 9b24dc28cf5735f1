r"""``grasp-record``: every topic of the package's graph into a rosbag2 bag, without rosbag2.

For machines with rclpy from the package index and no ROS install (no ``ros2 bag``)::

    grasp-record runs/filtered                    # mcap, until Ctrl-C or SIGTERM
    hand_sim_node --ros-args --params-file config/paper_scenario.yaml \\
        -p use_sim_time:=true -p start.wait_for_recorder:=grasp_recorder
    grasp-analyze runs/filtered

It subscribes to every topic of the topic table (:data:`grasp_safety_filter.io.topics.TOPICS`)
with the table's reliability and durability and a deep reader history (a busy recorder must
not lose samples it has not taken yet), and writes each message as it arrives, as CDR,
stamped with its arrival time, with the package's
:class:`~grasp_safety_filter.io.bag.BagRecorder`: the bag is what ``ros2 bag record -s
mcap`` on those topics would write (Jazzy metadata, the table's offered QoS), and is closed
with its metadata on SIGINT or SIGTERM. A simulator started with
``start.wait_for_recorder`` set to this node's name (``--node-name``, default
``grasp_recorder``) starts its run only once the recorder is subscribed to every topic.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder
from grasp_safety_filter.io.interrupts import record_termination_requests
from grasp_safety_filter.io.messages import rclpy_message_class
from grasp_safety_filter.nodes.spin_node import make_executor

#: The recorder's default node name (what ``start.wait_for_recorder`` names).
RECORDER_NODE_NAME = 'grasp_recorder'

#: Reader history per topic, messages.
READER_DEPTH = 10000

#: Longest wait of one spin, s (how soon a signal is noticed).
SPIN_PERIOD = 0.1


def _writer(recorder: BagRecorder, topic: str) -> Callable[[bytes], None]:
    def write(data: bytes) -> None:
        recorder.write_cdr(topic, time.time_ns(), data)

    return write


def _subscribe_all(node: Node, recorder: BagRecorder) -> None:
    """Subscribe to every table topic with its offered QoS and a deep history, raw."""
    for spec in topics.TOPICS:
        offered = spec.qos.to_rclpy()
        qos = QoSProfile(
            depth=READER_DEPTH,
            reliability=offered.reliability,
            durability=offered.durability,
        )
        node.create_subscription(
            rclpy_message_class(spec.msgtype),
            spec.name,
            _writer(recorder, spec.name),
            qos,
            raw=True,
        )


def record(bag: Path, node_name: str = RECORDER_NODE_NAME, storage: str = 'mcap') -> int:
    """Record every table topic to ``bag`` until SIGINT or SIGTERM; return the exit code.

    The signals are recorded, never raised (as in the nodes): the loop ends at its next
    turn, and nothing is cut short, neither the set-up (rclpy imports each message type's
    support while subscribing) nor a write nor the closing of the bag. A signal during
    the set-up ends the recording as soon as it is made; a second one changes nothing.
    """
    termination = record_termination_requests()
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(node_name)
    executor = make_executor(node.context)
    executor.add_node(node)
    try:
        with BagRecorder(bag, storage) as recorder:
            _subscribe_all(node, recorder)
            node.get_logger().info(f'recording {len(topics.TOPICS)} topics to {bag}')
            while rclpy.ok() and not termination.requested:
                executor.spin_once(timeout_sec=SPIN_PERIOD)
            counts = {topic: n for topic, n in recorder.counts.items() if n}
            node.get_logger().info(f'closing {bag}: {counts}')
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(args: list[str] | None = None) -> int:
    """Entry point of ``grasp-record``."""
    parser = argparse.ArgumentParser(
        prog='grasp-record', description=__doc__.split('\n', 1)[0].split(': ', 1)[1]
    )
    parser.add_argument('bag', type=Path, help='bag directory to create (must not exist)')
    parser.add_argument(
        '--node-name', default=RECORDER_NODE_NAME, help='the recorder node name'
    )
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    options = parser.parse_args(args)
    if options.bag.exists():
        print(f'grasp-record: {options.bag} exists already', file=sys.stderr)
        return 2
    return record(options.bag, options.node_name, options.storage)


if __name__ == '__main__':
    sys.exit(main())
