"""The filter node's start-up advice in its log: once, at the first state it ticks on.

The advice (:mod:`~grasp_safety_filter.control.startup_advice`) costs a linear program
(~2 ms; its first-call costs are paid by the node's spare tick at start-up,
:mod:`~grasp_safety_filter.nodes.tick_kernels`), so the tick only keeps its state; the
advice is computed when the node takes its log lines, after the tick's answer is out. A new
filter configuration (parameters set at run time) gets its own advice at the next tick.
"""

from __future__ import annotations

from typing import Any

from grasp_safety_filter.control.startup_advice import rest_state, startup_advice
from grasp_safety_filter.io.messages import DiagnosticLevel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.grasp_watch import LogLine

#: The first word of every advice line, so that a log reader finds them.
PREFIX = 'start-up advice'


class StartupLog:
    """Holds the first ticked state until the advice on it is logged (module docstring)."""

    def __init__(self, model: Any) -> None:
        """Wait for a state of ``model`` (a ``GraspModel``)."""
        self._model = model
        self._state: GraspState | None = None
        self._due = True

    def first_state(self, state: GraspState) -> None:
        """Keep ``state`` if no advice was given for this configuration yet."""
        if self._due and self._state is None:
            self._state = state

    def again(self) -> None:
        """Give the advice again, on the next ticked state (a new filter configuration)."""
        self._due = True
        self._state = None

    def take(self, safety_filter: Any) -> list[LogLine]:
        """Return the advice's lines once a state is kept (WARN if it flags the grasp), else []."""
        if self._state is None:
            return []
        state, self._state, self._due = self._state, None, False
        advice = startup_advice(safety_filter, rest_state(self._model, state))
        level = DiagnosticLevel.WARN if advice.warns else DiagnosticLevel.OK
        return [LogLine(level, f'{PREFIX} ({advice.verdict}): {line}') for line in advice.lines()]
