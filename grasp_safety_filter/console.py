"""Console entry points of the ``grasp-*`` tools that run or record: signals at once.

A tool spends its first second importing numpy, Pinocchio, rosbags and matplotlib. A
SIGINT in that time would end it with a ``KeyboardInterrupt`` traceback and a SIGTERM
without a word; through these entry points both are a :class:`SignalInterrupt` from the
first instant, and the tool exits with status 130 and one line. ``grasp-record``, which
signals stop by design, only records them and exits 0. This module imports nothing heavy
before the handlers are in place.
"""

from __future__ import annotations

import sys
from typing import Any

from grasp_safety_filter.io.interrupts import (
    interrupt_on_signals,
    record_termination_requests,
    signal_name,
)

INTERRUPTED = 130
"""Exit status of a tool stopped by SIGINT or SIGTERM (128 + SIGINT, as a shell reports)."""


def _ignore_unraisable(unraisable: Any) -> None:
    """``sys.unraisablehook`` of a tool that was stopped: its one line is all it says."""


class _HeldUnraisables:
    """``sys.unraisablehook`` that keeps each report as text until the tool's end is known.

    An interrupt can leave a library's object half-built (pyparsing's while matplotlib
    imports, llvmlite's while numba compiles), whose ``__del__`` then fails when the
    interrupt's traceback is dropped or as the interpreter exits. A stopped tool drops
    these reports; one that was not prints them as Python would have. Kept as text, not
    as the objects: holding an object being finalised would bring it back to life.
    """

    def __init__(self) -> None:
        self.reports: list[str] = []

    def __call__(self, unraisable: Any) -> None:
        import traceback

        where = unraisable.err_msg or 'Exception ignored in'
        if unraisable.object is not None:
            where = f'{where}: {unraisable.object!r}'
        exception = traceback.format_exception(
            unraisable.exc_type, unraisable.exc_value, unraisable.exc_traceback
        )
        self.reports.append(where + '\n' + ''.join(exception))


def _run(
    prog: str, function: str, argv: list[str] | None, module: str = 'grasp_safety_filter.cli'
) -> int:
    held = _HeldUnraisables()
    sys.unraisablehook = held
    status: int | None = None
    try:
        with interrupt_on_signals():
            import importlib

            status = int(getattr(importlib.import_module(module), function)(argv))
    except KeyboardInterrupt as interrupt:
        print(
            f'\n{prog}: interrupted by {signal_name(interrupt)} while starting: nothing written',
            file=sys.stderr,
        )
        status = INTERRUPTED
    finally:
        if status == INTERRUPTED:
            sys.unraisablehook = _ignore_unraisable
        else:  # finished, or failed: what Python would have said, said now
            sys.unraisablehook = sys.__unraisablehook__
            for report in held.reports:
                print(report, end='', file=sys.stderr)
    assert status is not None  # set on every path that gets here
    return status


def demo(argv: list[str] | None = None) -> int:
    """Run ``grasp-demo`` (:func:`grasp_safety_filter.cli.demo_main`)."""
    return _run('grasp-demo', 'demo_main', argv)


def analyze(argv: list[str] | None = None) -> int:
    """Run ``grasp-analyze`` (:func:`grasp_safety_filter.cli.analyze_main`)."""
    return _run('grasp-analyze', 'analyze_main', argv)


def campaign(argv: list[str] | None = None) -> int:
    """Run ``grasp-campaign`` (:func:`grasp_safety_filter.campaign.command.main`)."""
    return _run('grasp-campaign', 'main', argv, 'grasp_safety_filter.campaign.command')


def record(argv: list[str] | None = None) -> int:
    """Run ``grasp-record``: SIGINT and SIGTERM end it with status 0 at any time.

    They are how a recording ends, so from the first instant they are only recorded (see
    :func:`grasp_safety_filter.nodes.recorder_node.record`): one that came while the
    recorder imported rclpy ends it before it starts.
    """
    termination = record_termination_requests()
    from grasp_safety_filter.nodes.recorder_node import main

    if termination.requested:
        return 0
    return main(argv)
