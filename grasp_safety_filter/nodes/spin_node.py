"""A node process's body: rclpy initialised, one node spun, everything cleaned up.

:func:`spin_node`: a bad parameter ends the process with one line on stderr and exit code 2;
SIGINT and SIGTERM, once or repeatedly and at any moment, end it quietly with exit code 0.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
import signal
import sys
from typing import Any

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.interrupts import record_termination_requests, TERMINATION_SIGNALS
from grasp_safety_filter.io.parameters import load_parameter_file, ParameterError
from grasp_safety_filter.io.ros_arguments import parse_ros_arguments

#: Errors that mean a node was configured wrongly (its parameters, its model, its initial
#: grasp, its ROS arguments): :func:`spin_node` reports them in one line and exits with
#: EXIT_BAD_PARAMETERS.
STARTUP_ERRORS: tuple[type[Exception], ...] = (
    ConfigError,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    rclpy_implementation.RCLInvalidROSArgsError,
    rclpy_implementation.UnknownROSArgsError,
)

#: Exit code of a node that refused its configuration (as argparse's usage errors).
EXIT_BAD_PARAMETERS = EXIT_CONFIG_ERROR

#: Longest wait of the spin loop before it checks for SIGINT or SIGTERM, s.
SIGNAL_CHECK_PERIOD = 0.1


def spin_node(
    node_factory: Callable[..., Node],
    args: list[str] | None = None,
    executor_factory: Callable[[Any], Any] | None = None,
) -> None:
    """Initialise rclpy, spin one node until shutdown, SIGINT or SIGTERM, and clean up (Jazzy).

    The body of a node process. SIGINT and SIGTERM (one, or a second while cleaning up, as
    ``ros2 launch`` and ``timeout`` send them) end it quietly; so does shutting the context
    down. It returns with both signals ignored, so that one arriving while the interpreter
    exits cannot kill the process.

    Args:
        node_factory: Builds the node; called with ``global_arguments`` (an EndpointNode).
        args: The process's arguments (default ``sys.argv``).
        executor_factory: Builds the executor from the context (default
            :func:`make_executor`).

    Raises:
        SystemExit: With :data:`EXIT_BAD_PARAMETERS` after printing one line on stderr, when
            the node refuses its parameters (one of :data:`STARTUP_ERRORS`).
    """
    arguments = list(sys.argv if args is None else args)
    # The console entry point records the signals from the process's first instant.
    termination = record_termination_requests()
    context = rclpy.get_default_context()
    node = None
    executor = None
    error_line = None
    try:
        _init_rclpy(arguments)
        if not termination.requested:
            node = node_factory(global_arguments=arguments)
            executor = (executor_factory or make_executor)(context)
            executor.add_node(node)
        while not termination.requested and context.ok():
            try:
                executor.spin_once(timeout_sec=SIGNAL_CHECK_PERIOD)
            except ExternalShutdownException:
                break
            except Exception:
                if context.ok():
                    raise
                break  # a callback cut short by the node's own shutdown (the simulator's end)
    except STARTUP_ERRORS as error:
        program = Path(arguments[0]).name if arguments else 'node'
        unknown = isinstance(error, rclpy_implementation.UnknownROSArgsError)
        error_line = config_error_line(
            program, f'unknown ROS arguments {error}' if unknown else error
        )
    finally:
        _clean_up(executor, node)
        for signum in TERMINATION_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)
    if error_line is not None:
        print(error_line, file=sys.stderr)
        raise SystemExit(EXIT_BAD_PARAMETERS)


def make_executor(context: Any) -> Any:
    """Return the executor the nodes spin in: rclpy's events executor where it is.

    Measured with ``grasp-bench-ros`` on the paper's graph (2-core machine, same run
    length): it halves the CPU each node spends around its callbacks (filter node 3.6 ->
    2.0 ms per tick, simulator 3.4 -> 2.5 ms) against ``SingleThreadedExecutor``, which
    builds its wait set anew for every callback. Both run every callback in this thread.
    """
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # an rclpy without it (before Jazzy)
        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)


def wait_set_executor(context: Any) -> Any:
    """Return rclpy's ``SingleThreadedExecutor``: it honours callback groups.

    For a node that polls its streams (:meth:`~grasp_safety_filter.nodes.base_node.
    EndpointNode.subscribe_polled`): this executor leaves them alone, where the events
    executor takes (and converts) every message they receive.
    """
    return SingleThreadedExecutor(context=context)


def _init_rclpy(arguments: list[str]) -> None:
    """Initialise the default context without rclpy's signal handlers.

    The parameter files are read first, by this package's loader: rcl would refuse a file
    that is missing or not YAML with an ERROR log line of its own before the node's message.

    Raises:
        ParameterError: A parameter file cannot be read, or rcl refuses the arguments (a
            malformed ``-p`` rule, a flag without its value).
    """
    for path in parse_ros_arguments(arguments).params_files:
        load_parameter_file(path)
    try:
        rclpy.init(args=arguments, signal_handler_options=SignalHandlerOptions.NO)
    except rclpy_implementation.RCLError as error:
        raise ParameterError(f'ROS arguments refused: {error}') from None


def _clean_up(executor: Any, node: Node | None) -> None:
    """Shut the executor down, destroy the node and shut rclpy down, whatever is left.

    Once the context is shut down, rclpy may refuse to destroy what it already invalidated
    (``RuntimeError``, e.g. ``InvalidHandle``): nothing is left to clean up then.
    """
    steps: list[Callable[[], Any]] = []
    if executor is not None:
        steps.append(executor.shutdown)
    if node is not None:
        steps.append(node.destroy_node)
    for step in steps:
        try:
            step()
        except RuntimeError:
            if rclpy.ok():
                raise
    rclpy.try_shutdown()
