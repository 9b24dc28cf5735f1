"""``grasp-demo --set NAME=VALUE`` types its value as a parameter file and ``-p`` do."""

import argparse
from pathlib import Path

import pytest

from grasp_safety_filter.cli import demo_main, parse_override
from grasp_safety_filter.io.parameters import load_parameter_file, parse_parameter_value


@pytest.mark.parametrize(
    'text',
    ['1e-5', '1E5', '-2.5e+3', '1.0', '3', 'true', '[0.1, 1e-3]', '"1e-5"', 'osqp', '1_000'],
)
def test_set_types_a_value_as_a_file_and_dash_p_do(tmp_path: Path, text: str) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text(f'/**:\n  ros__parameters:\n    x: {text}\n', encoding='utf-8')
    name, value = parse_override(f'x={text}')
    assert name == 'x'
    expected = parse_parameter_value(text)
    assert (value, type(value).__name__) == (expected, type(expected).__name__)
    assert value == load_parameter_file(path)['/**']['x']


def test_set_reads_an_exponent_without_a_dot_as_a_double() -> None:
    assert parse_override('osqp.eps_abs=1e-5') == ('osqp.eps_abs', 1e-5)
    assert isinstance(parse_override('osqp.eps_abs=1e-5')[1], float)


@pytest.mark.parametrize('text', ['x', '=1', 'x=', 'x={a: 1}', 'x=[1'])
def test_set_refuses_a_malformed_value_as_an_argument_error(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError):
        parse_override(text)


def test_demo_reports_a_malformed_set_as_a_usage_error(capsys) -> None:
    with pytest.raises(SystemExit) as caught:
        demo_main(['--set', 'x={a: 1}'])
    assert caught.value.code == 2
    assert 'expected a value or a list of values' in capsys.readouterr().err
