"""The README's commands, the docs' console scripts and the generated tables stay true."""

from __future__ import annotations

from pathlib import Path
import re

import pytest

from grasp_safety_filter.io.readme_tables import FILES, render, tables

REPO = Path(__file__).resolve().parent.parent
README = (REPO / 'README.md').read_text()
DOCS = [REPO / 'README.md', *sorted((REPO / 'docs').glob('*.md'))]


@pytest.mark.parametrize('name', FILES)
def test_generated_tables_are_current(name):
    text = (REPO / name).read_text()
    assert any(f'<!-- {section}:begin -->' in text for section in tables()), name
    assert render(text) == text, 'run: python -m grasp_safety_filter.io.readme_tables'


def test_readme_keeps_the_topics_and_docs_parameters_keeps_the_parameters():
    assert '<!-- topics:begin -->' in README
    assert '<!-- parameters:begin -->' in (REPO / 'docs' / 'parameters.md').read_text()


def test_readme_starts_with_the_two_commands_and_ci_runs_the_test_one():
    first_block = re.search(r'```sh\n(.*?)```', README, re.DOTALL)[1].splitlines()
    assert [line.split('#')[0].strip() for line in first_block] == ['make demo', 'make test']
    assert 'make test' in (REPO / '.ci' / 'run').read_text()


@pytest.mark.parametrize('path', DOCS, ids=lambda path: path.name)
def test_every_console_script_named_is_installed(path):
    setup = (REPO / 'setup.py').read_text()
    for command in sorted(set(re.findall(r'\b(grasp-[a-z-]+)', path.read_text()))):
        assert f"'{command} = " in setup or f'"{command} = ' in setup, command


def _anchors(text: str) -> set[str]:
    """Return GitHub's anchors of the headings of a markdown text (outside code blocks)."""
    prose = re.sub(r'^```.*?^```', '', text, flags=re.DOTALL | re.MULTILINE)
    headings = re.findall(r'^#+ (.*)$', prose, re.MULTILINE)
    return {re.sub(r'[^\w\- ]', '', heading.lower()).replace(' ', '-') for heading in headings}


@pytest.mark.parametrize('path', DOCS, ids=lambda path: path.name)
def test_every_relative_link_resolves(path):
    for target in re.findall(r'\]\(([^)\s]+)\)', path.read_text()):
        if '://' in target:
            continue
        name, _, anchor = target.partition('#')
        linked = path.parent / name if name else path
        assert linked.exists(), target
        assert not anchor or anchor in _anchors(linked.read_text()), target
