"""``diagnostic_msgs/DiagnosticArray``: levels, reports and their key-value pairs."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import MessageError
from grasp_safety_filter.io.messages.fields import (
    checked_names,
)
from grasp_safety_filter.io.messages.namespace import byte_value, MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    header_msg,
    Stamp,
    time_from_msg,
)


class DiagnosticLevel(IntEnum):
    """``diagnostic_msgs/DiagnosticStatus`` levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


def format_diagnostic_value(value: Any) -> str:
    """Format a value as diagnostic text: floats with ``repr`` (``float()`` restores them)."""
    if isinstance(value, bool | np.bool_):
        return 'true' if value else 'false'
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return repr(float(value))
    return str(value)


@dataclass(frozen=True)
class DiagnosticReport:
    """One ``DiagnosticStatus``.

    Attributes:
        name: Component name, e.g. ``"safety_filter"``.
        level: OK, WARN, ERROR or STALE.
        message: One-line summary.
        values: Key/value pairs (values already text: see :func:`format_diagnostic_value`).
        hardware_id: Hardware identifier, empty for software components.

    """

    name: str
    level: DiagnosticLevel
    message: str
    values: dict[str, str] = field(default_factory=dict)
    hardware_id: str = ''

    @classmethod
    def create(
        cls,
        name: str,
        level: DiagnosticLevel | int,
        message: str,
        values: Mapping[str, Any] | None = None,
        hardware_id: str = '',
    ) -> DiagnosticReport:
        """Build a report, formatting the values with :func:`format_diagnostic_value`."""
        text = {str(k): format_diagnostic_value(v) for k, v in (values or {}).items()}
        return cls(name, DiagnosticLevel(level), message, text, hardware_id)


@dataclass(frozen=True)
class DiagnosticsData:
    """A parsed DiagnosticArray.

    Attributes:
        t: Header stamp, s.
        reports: The statuses, in message order.

    """

    t: float
    reports: tuple[DiagnosticReport, ...]

    def report(self, name: str) -> DiagnosticReport:
        """Return the status named ``name`` (KeyError naming the known ones if absent)."""
        for report in self.reports:
            if report.name == name:
                return report
        raise KeyError(f'no diagnostic status {name!r}; have {[r.name for r in self.reports]}')


def diagnostics_to_msg(
    msgs: MessageNamespace, t: Stamp, reports: DiagnosticReport | Sequence[DiagnosticReport]
) -> Any:
    """Build a ``diagnostic_msgs/DiagnosticArray`` of one or more statuses."""
    if isinstance(reports, DiagnosticReport):
        reports = [reports]
    statuses = [
        msgs.DiagnosticStatus(
            level=msgs.byte(DiagnosticLevel(r.level)),
            name=r.name,
            message=r.message,
            hardware_id=r.hardware_id,
            values=[msgs.KeyValue(key=k, value=v) for k, v in r.values.items()],
        )
        for r in reports
    ]
    return msgs.DiagnosticArray(header=header_msg(msgs, t, ''), status=statuses)


def diagnostics_from_msg(msg: Any, source: str = 'diagnostics') -> DiagnosticsData:
    """Parse a DiagnosticArray (``level`` as int or 1-byte ``bytes``).

    Raises:
        MessageError: A level outside OK..STALE or a duplicate key within a status.

    """
    reports = []
    for status in msg.status:
        level = byte_value(status.level)
        if level not in {int(member) for member in DiagnosticLevel}:
            raise MessageError(
                f'{source}: status {status.name!r} level must be 0..3, got {level!r}'
            )
        keys = checked_names(
            f'{source}: status {status.name!r}', [kv.key for kv in status.values], 'key'
        )
        values = dict(zip(keys, (str(kv.value) for kv in status.values), strict=True))
        reports.append(
            DiagnosticReport(
                name=str(status.name),
                level=DiagnosticLevel(level),
                message=str(status.message),
                values=values,
                hardware_id=str(status.hardware_id),
            )
        )
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return DiagnosticsData(t=t, reports=tuple(reports))
