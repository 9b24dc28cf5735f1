"""The parameter tables of docs/parameters.md, from the schemas."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from grasp_safety_filter.io.parameters import (
    ParameterSpec,
)


def _markdown_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, list):
        return '[' + ', '.join(_markdown_value(item) for item in value) + ']'
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def parameter_table_markdown(schema: Iterable[ParameterSpec]) -> str:
    """Render parameters as a Markdown table: name, type, default, admissible, description.

    Read-only parameters (read once at start-up) are marked with ``(ro)``.
    """
    lines = [
        '| Parameter | Type | Default | Admissible | Description |',
        '|---|---|---|---|---|',
    ]
    for spec in schema:
        cells = [
            f'`{spec.name}`' + (' (ro)' if spec.read_only else ''),
            spec.type.value,
            f'`{_markdown_value(spec.default)}`',
            spec.constraint_text() or 'any',
            spec.description,
        ]
        lines.append('| ' + ' | '.join(cell.replace('|', '\\|') for cell in cells) + ' |')
    return '\n'.join(lines) + '\n'
