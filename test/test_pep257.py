"""ament_pep257 over the package's Python files (ROS 2's docstring check)."""

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO = Path(__file__).resolve().parent.parent
PATHS = ('grasp_safety_filter', 'hand_sim_node', 'tools', 'launch', 'test', 'setup.py')

# The package writes Google-style docstrings ("Args:" sections, summary on the first line):
# the google convention instead of ament's default list, which checks numpy-style section
# underlines (D406, D407) and the summary on the second line (D213). Missing docstrings
# (D100-D107) are left to ruff, as in ament's default.
ARGS = ('--convention', 'google', '--add-ignore', *(f'D10{i}' for i in range(8)))


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=[*(str(REPO / path) for path in PATHS), *ARGS])
    assert rc == 0, 'Found code style errors / warnings'
