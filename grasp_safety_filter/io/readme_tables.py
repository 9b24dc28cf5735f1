"""The topic and parameter tables of the documentation, generated from the topics and schemas.

A generated section is the text between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``,
NAME a key of :func:`tables`: ``topics`` in README.md, ``parameters`` in docs/parameters.md.
``python -m grasp_safety_filter.io.readme_tables [FILE ...]`` rewrites every section of each
FILE in place (default: :data:`FILES`, from the repository's root); a test checks that both
files are current.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
import re
import sys
from typing import Any

from grasp_safety_filter.io.parameters import ParameterSpec
from grasp_safety_filter.io.schemas import (
    COMMAND_PARAMETERS,
    GRASP_CHECK_PARAMETERS,
    HAND_SIM_PARAMETERS,
    MARKER_PARAMETERS,
    MODEL_PARAMETERS,
    NOMINAL_CONTROLLER_PARAMETERS,
    SAFETY_FILTER_PARAMETERS,
    STREAM_PARAMETERS,
)
from grasp_safety_filter.io.topics import TOPICS, TopicSpec

#: The files with generated sections, relative to the repository's root.
FILES = ('README.md', 'docs/parameters.md')


def _markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """Return a Markdown table (a ``|`` inside a cell escaped)."""
    lines = [header, ['---'] * len(header)]
    lines += [[cell.replace('|', '\\|') for cell in row] for row in rows]
    return '\n'.join('| ' + ' | '.join(cells) + ' |' for cells in lines) + '\n'


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


def parameter_table_markdown(specs: Iterable[ParameterSpec]) -> str:
    """Return a table of parameters: name (``(ro)``: read-only), type, default, range, text."""
    return _markdown_table(
        ('Parameter', 'Type', 'Default', 'Admissible', 'Description'),
        (
            (
                f'`{spec.name}`' + (' (ro)' if spec.read_only else ''),
                spec.type.value,
                f'`{_markdown_value(spec.default)}`',
                spec.constraint_text() or 'any',
                spec.description,
            )
            for spec in specs
        ),
    )


def topic_table_markdown(specs: Iterable[TopicSpec] = TOPICS) -> str:
    """Return a table of topics: name, type, publishers, QoS, description."""
    return _markdown_table(
        ('Topic', 'Type', 'Published by', 'QoS', 'Content'),
        (
            (
                f'`{spec.name}`',
                f'`{spec.msgtype}`',
                ', '.join(f'`{p}`' for p in spec.publishers),
                spec.qos.text,
                spec.description,
            )
            for spec in specs
        ),
    )


def parameter_tables() -> str:
    """Return the parameter tables: the shared model section, then each node's own."""
    sections = (
        ('Shared by all nodes (`/**`)', MODEL_PARAMETERS),
        ('`hand_sim_node`', HAND_SIM_PARAMETERS),
        ('`nominal_controller_node`', NOMINAL_CONTROLLER_PARAMETERS + GRASP_CHECK_PARAMETERS),
        ('`safety_filter_node`', SAFETY_FILTER_PARAMETERS + COMMAND_PARAMETERS),
        (
            'Input streams of both controllers (`nominal_controller_node`, `safety_filter_node`)',
            STREAM_PARAMETERS,
        ),
        ('`grasp_markers_node`', MARKER_PARAMETERS),
    )
    return '\n\n'.join(
        f'## {title}\n\n{parameter_table_markdown(specs).strip()}' for title, specs in sections
    )


def tables() -> dict[str, str]:
    """Return ``{marker: generated markdown}`` for every generated section."""
    return {'topics': topic_table_markdown().strip(), 'parameters': parameter_tables()}


def render(text: str) -> str:
    """Return ``text`` with each of its generated sections regenerated (it must have one)."""
    found = False
    for name, table in tables().items():
        pattern = re.compile(rf'(<!-- {name}:begin -->\n).*?(<!-- {name}:end -->)', re.DOTALL)
        found = found or bool(pattern.search(text))
        text = pattern.sub(lambda match, table=table: f'{match[1]}{table}\n{match[2]}', text)
    if not found:
        raise ValueError(f'no <!-- NAME:begin --> ... <!-- NAME:end -->, NAME in {list(tables())}')
    return text


def main(argv: list[str] | None = None) -> int:
    """Rewrite the generated sections of the given markdown files (default: FILES) in place."""
    args = sys.argv[1:] if argv is None else argv
    for path in map(Path, args or FILES):
        path.write_text(render(path.read_text()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
