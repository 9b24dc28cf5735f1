"""The package finds its own config/ with or without an ament prefix (rclpy from pip)."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parent.parent

FIND_CONFIG = (
    'import ament_index_python, grasp_safety_filter.io.paths as p; print(p.config_path())'
)


def run_python(code: str, **env: str | None) -> subprocess.CompletedProcess[str]:
    environment = {k: v for k, v in os.environ.items() if k != 'AMENT_PREFIX_PATH'}
    environment.update({k: v for k, v in env.items() if v is not None})
    return subprocess.run(
        [sys.executable, '-c', code], env=environment, capture_output=True, text=True, check=False
    )


@pytest.mark.parametrize(
    'ament_prefix_path',
    [None, '', '/nonexistent/prefix', str(REPO / 'test')],
    ids=['unset', 'empty', 'missing-prefix', 'prefix-without-the-package'],
)
def test_config_is_found_whatever_the_ament_prefix(ament_prefix_path):
    """The wheels' ament_index_python raises OSError without a prefix: never let it out."""
    result = run_python(FIND_CONFIG, AMENT_PREFIX_PATH=ament_prefix_path)
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()) == REPO / 'config' / 'paper_scenario.yaml'


def test_an_ament_prefix_holding_the_package_is_used(tmp_path):
    share = tmp_path / 'share' / 'grasp_safety_filter'
    (share / 'config').mkdir(parents=True)
    index = tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'grasp_safety_filter').write_text('', encoding='utf-8')
    result = run_python(FIND_CONFIG, AMENT_PREFIX_PATH=str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()) == share / 'config' / 'paper_scenario.yaml'


@pytest.mark.parametrize('tool', ['grasp-demo', 'grasp-analyze', 'grasp-model-report'])
def test_tools_start_without_an_ament_prefix(tool):
    executable = Path(sys.executable).parent / tool
    environment = {k: v for k, v in os.environ.items() if k != 'AMENT_PREFIX_PATH'}
    result = subprocess.run(
        [str(executable), '--help'], env=environment, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout
