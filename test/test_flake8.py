"""ament_flake8 over the package's Python files (ROS 2's code style check)."""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO = Path(__file__).resolve().parent.parent
# Explicit paths: a checkout's .venv/ must not be linted.
PATHS = ('grasp_safety_filter', 'hand_sim_node', 'tools', 'launch', 'test', 'setup.py')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    config = REPO / 'test' / 'flake8.ini'
    rc, errors = main_with_errors(
        argv=['--config', str(config), *(str(REPO / path) for path in PATHS)]
    )
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
