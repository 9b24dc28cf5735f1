"""A parameter file is parsed once for all the nodes that read it, in time linear in its size."""

import os
from pathlib import Path

import pytest

from grasp_safety_filter.io import parameters
from grasp_safety_filter.io.parameters import files as parameter_files
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)


def bulk_section(entries: int) -> str:
    """Return a section for another node: ``entries`` doubles and an array of as many."""
    lines = ['bulk_data_recorder:', '  ros__parameters:', '    table:']
    lines += [f'      entry_{i}: {i * 0.25}' for i in range(entries)]
    lines.append('    samples: [' + ', '.join(f'{i}.5e-3' for i in range(entries)) + ']')
    return '\n'.join(lines) + '\n'


@pytest.fixture
def parses(monkeypatch) -> list[Path]:
    """Record every YAML parse of a parameter file."""
    calls: list[Path] = []
    read = parameter_files._read_document

    def counting(path: Path):
        calls.append(path)
        return read(path)

    parameter_files._parsed_file.cache_clear()
    monkeypatch.setattr(parameter_files, '_read_document', counting)
    yield calls
    parameter_files._parsed_file.cache_clear()


@pytest.fixture
def large_scenario(tmp_path: Path) -> Path:
    """Write the paper scenario with a section for another node, about 6 MB in all."""
    path = tmp_path / 'large_scenario.yaml'
    path.write_text(
        config_path().read_text(encoding='utf-8') + bulk_section(200_000), encoding='utf-8'
    )
    assert path.stat().st_size > 5e6
    return path


def test_the_three_nodes_parse_a_large_file_once(large_scenario: Path, parses) -> None:
    nodes = (HAND_SIM_NODE, NOMINAL_CONTROLLER_NODE, SAFETY_FILTER_NODE)
    values = {node: load_node_parameters(large_scenario, node) for node in nodes}
    assert len(parses) == 1
    packaged = load_node_parameters(config_path(), HAND_SIM_NODE)
    relative = {'model.urdf_file'}  # resolved against each file's own directory
    assert {k: v for k, v in values[HAND_SIM_NODE].items() if k not in relative} == {
        k: v for k, v in packaged.items() if k not in relative
    }
    assert len(parses) == 2  # the packaged file, once


def test_a_changed_file_is_parsed_again(tmp_path: Path, parses) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text('n:\n  ros__parameters: {a: 1.0}\n', encoding='utf-8')
    assert parameters.load_parameter_file(path) == {'/n': {'a': 1.0}}
    assert parameters.load_parameter_file(path) == {'/n': {'a': 1.0}}
    assert len(parses) == 1
    path.write_text('n:\n  ros__parameters: {a: 2.0}\n', encoding='utf-8')
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert parameters.load_parameter_file(path) == {'/n': {'a': 2.0}}
    assert len(parses) == 2


def test_a_caller_changing_the_result_does_not_change_the_next(tmp_path: Path, parses) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text('n:\n  ros__parameters: {a: 1.0}\n', encoding='utf-8')
    first = parameters.load_parameter_file(path)
    first['/n']['a'] = 5.0
    first['/m'] = {}
    assert parameters.load_parameter_file(path) == {'/n': {'a': 1.0}}


def test_a_refused_file_is_refused_again(tmp_path: Path, parses) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text('n:\n  ros__parameters: {a: 1.0, a: 2.0}\n', encoding='utf-8')
    for _ in range(2):
        with pytest.raises(parameters.ParameterError, match="duplicate key 'a'"):
            parameters.load_parameter_file(path)


def test_yaml_work_grows_linearly_with_the_file(tmp_path: Path, monkeypatch) -> None:
    constructed = []
    construct = parameter_files._RosYamlLoader.construct_object

    def counting(self, node, deep=False):
        constructed.append(node)
        return construct(self, node, deep=deep)

    monkeypatch.setattr(parameter_files._RosYamlLoader, 'construct_object', counting)
    counts = []
    for entries in (1_000, 4_000):
        path = tmp_path / f'bulk_{entries}.yaml'
        path.write_text(bulk_section(entries), encoding='utf-8')
        constructed.clear()
        parameter_files._read_document(path)
        counts.append(len(constructed))
    # Each key, value and array element at most twice (the duplicate-key check's lookup).
    assert counts[0] <= 2 * 3 * 1_000 + 20
    assert counts[1] <= 4.1 * counts[0]
