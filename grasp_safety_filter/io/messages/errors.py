"""Message errors and bounded report texts: what a rejected input says, and at most how much."""

from __future__ import annotations

from collections.abc import Sequence

#: Longest text of a rejection or error report (status message, ``input.last_rejection``),
#: characters: a message with 100k names must not make every later /diagnostics huge.
MAX_REPORT_TEXT = 1000

#: Names listed in a rejection text before the rest are only counted.
NAMES_SHOWN = 5

# Longest text of one received name (or frame id) in a rejection text, characters.
MAX_NAME_TEXT = 64


def bounded_text(text: str, limit: int = MAX_REPORT_TEXT) -> str:
    """Return ``text``, cut to ``limit`` characters with a note of how many were cut."""
    if len(text) <= limit:
        return text
    note = f' ... ({len(text)} characters in all)'
    return text[: max(limit - len(note), 0)] + note[-limit:]


def name_list(names: Sequence[str], shown: int = NAMES_SHOWN) -> str:
    """Return ``['a', 'b', ... (N more)]``: the first ``shown`` names (bounded), a count."""
    listed = [repr(bounded_text(str(n), MAX_NAME_TEXT)) for n in list(names)[:shown]]
    if len(names) > shown:
        listed.append(f'... ({len(names) - shown} more)')
    return '[' + ', '.join(listed) + ']'


class MessageError(ValueError):
    """A message cannot be converted: bad values, lengths, names, frames or stamps."""


class StaleInputError(MessageError):
    """A message's stamp is older than the allowed age."""


class OutOfOrderError(MessageError):
    """A message's stamp is older than the last one accepted on its topic."""


class FutureStampError(MessageError):
    """A message's stamp is ahead of the clock by more than the allowed age."""
