"""The README's topic and parameter tables, generated from the topic table and the schemas.

``python -m grasp_safety_filter.io.readme_tables README.md`` rewrites them in place; a test
checks that the README's copy is current.
"""

from __future__ import annotations

from pathlib import Path
import re
import sys

from grasp_safety_filter.io.schemas import (
    COMMAND_PARAMETERS,
    GRASP_CHECK_PARAMETERS,
    HAND_SIM_PARAMETERS,
    MODEL_PARAMETERS,
    NOMINAL_CONTROLLER_PARAMETERS,
    parameter_table_markdown,
    SAFETY_FILTER_PARAMETERS,
    STREAM_PARAMETERS,
)
from grasp_safety_filter.io.topics import topic_table_markdown


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
    )
    return '\n\n'.join(
        f'### {title}\n\n{parameter_table_markdown(specs).strip()}' for title, specs in sections
    )


def tables() -> dict[str, str]:
    """Return ``{marker: generated markdown}`` for every generated section."""
    return {'topics': topic_table_markdown().strip(), 'parameters': parameter_tables()}


def render(text: str) -> str:
    """Return ``text`` with every ``<!-- name:begin -->...<!-- name:end -->`` regenerated."""
    for name, table in tables().items():
        pattern = re.compile(rf'(<!-- {name}:begin -->\n).*?(<!-- {name}:end -->)', re.DOTALL)
        if not pattern.search(text):
            raise ValueError(f'no <!-- {name}:begin --> ... <!-- {name}:end --> section')
        text = pattern.sub(lambda match, table=table: f'{match[1]}{table}\n{match[2]}', text)
    return text


def main(argv: list[str] | None = None) -> int:
    """Rewrite the generated sections of the given markdown file in place."""
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0] if args else 'README.md')
    path.write_text(render(path.read_text()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
