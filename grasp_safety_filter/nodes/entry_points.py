"""Console entry points of the three node processes: quiet on Ctrl-C from their first instant.

A node process spends its first few tenths of a second importing rclpy, Pinocchio and numpy
before :func:`~grasp_safety_filter.nodes.spin_node.spin_node` takes SIGINT and SIGTERM
over. A signal in that time (``ros2 launch`` started and stopped at once) would end it with
a ``KeyboardInterrupt`` traceback; through these entry points it exits 0 without a word,
as it does later. This module imports nothing heavy itself.
"""

from __future__ import annotations

import importlib

from grasp_safety_filter.io.interrupts import record_termination_requests

#: Console script name -> the module whose ``main(args)`` runs that node.
NODE_MODULES: dict[str, str] = {
    'hand_sim_node': 'hand_sim_node.node',
    'nominal_controller_node': 'grasp_safety_filter.nodes.nominal_controller_node',
    'safety_filter_node': 'grasp_safety_filter.nodes.safety_filter_node',
    'grasp_markers_node': 'grasp_safety_filter.nodes.grasp_markers_node',
}


def run_node(name: str, args: list[str] | None = None) -> None:
    """Import the node's module with SIGINT and SIGTERM recorded, not raised; run it.

    An exception raised by a signal handler in the middle of an import can be turned into
    an ``ImportError`` (an extension module initialising itself runs Python code), or be
    dropped where Python can only report it (a weakref callback of the import system). So
    the signals are only recorded: a request that came during the import ends the process
    quietly once the import is done, before anything is started; a later one is seen by
    :func:`~grasp_safety_filter.nodes.spin_node.spin_node`, which keeps the same record.
    """
    termination = record_termination_requests()
    module = importlib.import_module(NODE_MODULES[name])
    if termination.requested:
        raise SystemExit(0)
    module.main(args)


def hand_sim_node(args: list[str] | None = None) -> None:
    """Run ``hand_sim_node``."""
    run_node('hand_sim_node', args)


def nominal_controller_node(args: list[str] | None = None) -> None:
    """Run ``nominal_controller_node``."""
    run_node('nominal_controller_node', args)


def safety_filter_node(args: list[str] | None = None) -> None:
    """Run ``safety_filter_node``."""
    run_node('safety_filter_node', args)


def grasp_markers_node(args: list[str] | None = None) -> None:
    """``grasp_markers_node``: the grasp as RViz/Foxglove markers."""
    run_node('grasp_markers_node', args)
