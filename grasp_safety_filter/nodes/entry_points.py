"""Console entry points of the three node processes: quiet on Ctrl-C from their first instant.

A node process spends its first few tenths of a second importing rclpy, Pinocchio and numpy
before :func:`~grasp_safety_filter.nodes.base_node.spin_node` takes SIGINT and SIGTERM
over. A signal in that time (``ros2 launch`` started and stopped at once) would end it with
a ``KeyboardInterrupt`` traceback; through these entry points it exits 0 without a word,
as it does later. This module imports nothing heavy itself.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from types import FrameType
from typing import Any

#: Console script name -> the module whose ``main(args)`` runs that node.
NODE_MODULES: dict[str, str] = {
    'hand_sim_node': 'hand_sim_node.node',
    'nominal_controller_node': 'grasp_safety_filter.nodes.nominal_controller_node',
    'safety_filter_node': 'grasp_safety_filter.nodes.safety_filter_node',
}


#: Signals received while the node's module was imported (see :func:`run_node`).
_received: list[int] = []


def _exit_quietly(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)
    raise SystemExit(0)


def _exit_if_swallowed(unraisable: Any, default: Any = sys.__unraisablehook__) -> None:
    """``sys.unraisablehook``: the quiet exit raised where it cannot propagate still exits.

    A signal handled inside a weakref callback or a ``__del__`` (the import system has both)
    raises there, and Python would print "Exception ignored" and go on importing.
    """
    if isinstance(unraisable.exc_value, SystemExit) and _received:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    default(unraisable)


def run_node(name: str, args: list[str] | None = None) -> None:
    """Import the node's module with SIGINT and SIGTERM ending the process quietly, run it.

    The handler raises ``SystemExit`` wherever the import is. An extension module's
    initialisation may run Python code and drop the exception it raised, so the request is
    also recorded and honoured once the import is done; one raised where Python can only
    report it (a weakref callback) ends the process at once, before anything is started.
    """
    sys.unraisablehook = _exit_if_swallowed
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _exit_quietly)
    module = importlib.import_module(NODE_MODULES[name])
    if _received:
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
