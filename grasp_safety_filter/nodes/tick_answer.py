"""The safety filter's answer to a computed tick: u*, and the margins and status when due.

A tick whose state passed the grasp check gets u* (filtered, or u_nom with the filter off,
after the hold policy) on ``/hand/effort_command`` (and, as configured, in ros2_control's
form: :mod:`~grasp_safety_filter.nodes.command_output`), stamped with the tick's stamp. The margins
(``/safety_filter/margins``, :mod:`~grasp_safety_filter.io.margin_stream`) and the
``safety_filter`` status (:mod:`~grasp_safety_filter.nodes.filter_status`) follow on the
ticks the publication rate says (:mod:`~grasp_safety_filter.nodes.publication_rate`). A
result's margins and active rows are computed only when read: on those ticks. The answers
without a QP are :mod:`~grasp_safety_filter.nodes.held_commands`'.
"""

from __future__ import annotations

from collections.abc import Callable
import time

import numpy as np

from grasp_safety_filter.control.safety_filter import FilterResult, Margins
from grasp_safety_filter.io.diagnostic_keys import TickStatus
from grasp_safety_filter.io.margin_stream import MarginEncoder
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.topics import MARGINS
from grasp_safety_filter.nodes.command_output import CommandOutput
from grasp_safety_filter.nodes.filter_status import tick_status, TickContext
from grasp_safety_filter.nodes.held_commands import StatusBuilder
from grasp_safety_filter.nodes.outgoing import Outgoing
from grasp_safety_filter.nodes.publication_rate import PublicationRate


class TickAnswer:
    """Builds a computed tick's messages (module docstring).

    Args:
        msgs: Message classes to build.
        command: Builds the command messages.
        rate: The publication rate (which ticks carry the margins and the status).
        status: Builds the ``safety_filter`` status.

    Attributes:
        margin_stream: The ``/safety_filter/margins`` stream (row names only when due).

    """

    def __init__(
        self,
        msgs: MessageNamespace,
        command: CommandOutput,
        rate: PublicationRate,
        status: StatusBuilder,
    ) -> None:
        self.msgs = msgs
        self.margin_stream = MarginEncoder()
        self._command = command
        self._rate = rate
        self._status = status

    def messages(
        self,
        stamp: int,
        u: np.ndarray,
        result: FilterResult | None,
        margins_at_u_nom: Margins | None,
        filter_time: float,
        tick_start: float,
        context: Callable[[], TickContext],
        resumed: bool,
    ) -> list[Outgoing]:
        """Return the tick's command, then its margins and status when due.

        Args:
            stamp: The tick's stamp, integer ns: every message's.
            u: The command, (m,), N·m.
            result: The filter's result; None with the filter off.
            margins_at_u_nom: With the filter off, the margins at u_nom (else None).
            filter_time: The filter step's duration, s.
            tick_start: When the tick started (``time.perf_counter``), s.
            context: Gives the status's endpoint values (called only when it is due).
            resumed: The first tick after the input watchdog took over (the status goes
                out whatever the rate).
        """
        outgoing = self._command.messages(stamp, u)
        if self._rate.margins_due(stamp):
            margins = margins_at_u_nom if result is None else result.margins
            message = self.margin_stream.encode(self.msgs, stamp, margins.names, margins.array)
            outgoing.append(Outgoing(MARGINS, stamp, message))
        status = TickStatus.DISABLED if result is None else TickStatus.of(result.status)
        if self._rate.status_due(stamp, status, force=resumed):
            tick_time = time.perf_counter() - tick_start
            margins = margins_at_u_nom if result is None else result.margins
            level, text, values = tick_status(result, margins, filter_time, tick_time, context())
            outgoing.append(self._status(stamp, level, text, values))
        return outgoing
