"""How often the safety filter publishes its per-tick status and margins.

At 1 kHz a status on ``/diagnostics`` every tick floods it (``diagnostic_aggregator`` and
``rqt_robot_monitor`` expect a few per second) and costs the filter node a large message
per tick. :class:`PublicationRate` decides, per tick, whether the ``safety_filter`` status
and ``/safety_filter/margins`` go out:

- ``diagnostics.period`` (s of tick stamps, 0: every tick): a status whose value is
  *steady* (:data:`STEADY_STATUSES`: solved, nominal, switched off) and the same as the
  previous tick's goes out once per period. Every other tick's status goes out: a relaxed
  QP, a QP without a solution, rejected or missing input, and the first tick of each change
  of status. So nothing but repetitions of the same good news is left out, and every status
  carries the counts of all ticks by status so far (:meth:`counter_values`), from which the
  analysis counts the run's ticks exactly.
- ``margins.period`` (s, 0: every tick): the margins go out once per period.

Input rejected where no command answers it (before a controller's first tick, a bad tracker
sample) is reported at most once per :data:`REPORT_PERIOD_NS` of stamps per input, with the
count since the last report (:class:`ReportThrottle`): a stream refused at 1 kHz must not
cost a status message per sample.

Decisions depend only on tick stamps, never on the wall clock, so the ROS graph and the
lockstep runner publish the same messages.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.io.diagnostic_keys import Key, status_count, TickStatus

DIAGNOSTICS_PERIOD_PARAMETER = 'diagnostics.period'
MARGINS_PERIOD_PARAMETER = 'margins.period'
PUBLICATION_RATE_PARAMETERS = (DIAGNOSTICS_PERIOD_PARAMETER, MARGINS_PERIOD_PARAMETER)

#: Statuses whose repetitions are published once per ``diagnostics.period``.
STEADY_STATUSES = frozenset(
    {TickStatus.NOMINAL, TickStatus.SOLVED, TickStatus.DISABLED}
)


@dataclass(frozen=True)
class PublicationRateConfig:
    """The ``diagnostics.period`` and ``margins.period`` parameters.

    Attributes:
        diagnostics_period: Least stamp interval between two statuses of a steady run, s
            (>= 0; 0: every tick).
        margins_period: Least stamp interval between two margins messages, s (>= 0).

    """

    diagnostics_period: float = 0.0
    margins_period: float = 0.0

    def __post_init__(self) -> None:
        for name, value in (
            (DIAGNOSTICS_PERIOD_PARAMETER, self.diagnostics_period),
            (MARGINS_PERIOD_PARAMETER, self.margins_period),
        ):
            if not value >= 0.0:
                raise ValueError(f"parameter '{name}': expected a period >= 0 s, got {value!r}")

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> PublicationRateConfig:
        """Read the two periods from a node's values (missing: every tick)."""
        return cls(
            diagnostics_period=float(values.get(DIAGNOSTICS_PERIOD_PARAMETER, 0.0)),
            margins_period=float(values.get(MARGINS_PERIOD_PARAMETER, 0.0)),
        )


class PublicationRate:
    """Per-tick publication decisions and the tick counts by status (module docstring)."""

    def __init__(self, config: PublicationRateConfig | None = None) -> None:
        self.counts: Counter[TickStatus] = Counter()
        self._previous: TickStatus | None = None
        self._status_sent_ns: int | None = None
        self._margins_sent_ns: int | None = None
        self.configure(config or PublicationRateConfig())

    def configure(self, config: PublicationRateConfig) -> None:
        """Apply new periods from the next tick on; the counts go on."""
        self.config = config
        self._status_period_ns = round(config.diagnostics_period * 1e9)
        self._margins_period_ns = round(config.margins_period * 1e9)

    def status_due(self, stamp: int, status: TickStatus, force: bool = False) -> bool:
        """Count a tick of ``status`` stamped ``stamp`` (ns); return whether to publish it.

        ``force``: publish it whatever its status (e.g. the first tick after the watchdog).
        """
        self.counts[status] += 1
        repeated = status in STEADY_STATUSES and status == self._previous
        self._previous = status
        if force or not repeated or _due(stamp, self._status_sent_ns, self._status_period_ns):
            self._status_sent_ns = stamp
            return True
        return False

    def margins_due(self, stamp: int) -> bool:
        """Return whether the margins of the tick stamped ``stamp`` (ns) go out."""
        if _due(stamp, self._margins_sent_ns, self._margins_period_ns):
            self._margins_sent_ns = stamp
            return True
        return False

    def counter_values(self) -> dict[str, int]:
        """Return the counts as diagnostic values: ticks by status, and all ticks."""
        values = {status_count(status): n for status, n in self.counts.items()}
        values[Key.TICKS] = sum(self.counts.values())
        return values


def _due(stamp: int, last: int | None, period: int) -> bool:
    """Whether a period has passed since ``last`` (ns; a stamp going back counts as due)."""
    return last is None or period <= 0 or not 0 <= stamp - last < period


#: Least stamp interval between two reports of rejected input of one kind, ns.
REPORT_PERIOD_NS = 1_000_000_000


class ReportThrottle:
    """At most one report per :data:`REPORT_PERIOD_NS` of stamps per key (module docstring)."""

    def __init__(self) -> None:
        self._since: Counter[str] = Counter()
        self._reported_ns: dict[str, int] = {}

    def due(self, key: str, stamp_ns: int) -> int | None:
        """Count an event of ``key`` at ``stamp_ns`` (ns); return the count to report, or None.

        The count is of the events since the last report, this one included; a stamp going
        back counts as due.
        """
        self._since[key] += 1
        if not _due(stamp_ns, self._reported_ns.get(key), REPORT_PERIOD_NS):
            return None
        self._reported_ns[key] = stamp_ns
        return self._since.pop(key)
