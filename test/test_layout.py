"""The runtime never loads the benchmarks and studies (``grasp_tools``, the tools/ folder).

Each runtime entry point is imported in a fresh interpreter, as its console script would,
and ``grasp_tools`` must not be among the loaded modules afterwards; no module of the
runtime packages names it.
"""

from __future__ import annotations

import ast
from pathlib import Path
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parent.parent
RUNTIME_PACKAGES = ('grasp_safety_filter', 'hand_sim_node')
TOOLS = 'grasp_tools'

#: Runtime entry point -> the module a process of it imports first.
ENTRY_POINTS = {
    'hand_sim_node': 'hand_sim_node.node',
    'nominal_controller_node': 'grasp_safety_filter.nodes.nominal_controller_node',
    'safety_filter_node': 'grasp_safety_filter.nodes.safety_filter_node',
    'node entry points': 'grasp_safety_filter.nodes.entry_points',
    'grasp-demo, grasp-analyze, grasp-record, grasp-campaign': 'grasp_safety_filter.console',
    'grasp-campaign': 'grasp_safety_filter.campaign.command',
    'grasp-model-report': 'grasp_safety_filter.model_report',
    "the simulator node's MuJoCo plant": 'hand_sim_node.mujoco_plant',
    'launch files': 'grasp_safety_filter.io.launch_arguments',
}

PROBE = (
    'import importlib, sys\n'
    'importlib.import_module(sys.argv[1])\n'
    'print(" ".join(sorted(name for name in sys.modules if name.split(".")[0] == sys.argv[2])))\n'
)


def console_scripts() -> dict[str, str]:
    """Return setup.py's console scripts: name -> ``module:function``."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values, strict=True):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    specs = (ast.literal_eval(item) for item in value.elts)
                    return dict(
                        (part.strip() for part in spec.split('=', 1)) for spec in specs
                    )
    raise AssertionError('setup.py has no console_scripts')


def test_every_runtime_console_script_is_probed():
    scripts = console_scripts()
    runtime = {name: target for name, target in scripts.items() if not target.startswith(TOOLS)}
    assert {target.split(':')[0] for target in runtime.values()} <= set(ENTRY_POINTS.values())
    tools = {name for name, target in scripts.items() if target.startswith(TOOLS)}
    assert {'grasp-bench', 'grasp-bench-ros', 'grasp-bench-realtime'} <= tools


@pytest.mark.parametrize('module', ENTRY_POINTS.values(), ids=ENTRY_POINTS.keys())
def test_a_runtime_entry_point_loads_no_tool(module):
    result = subprocess.run(
        [sys.executable, '-c', PROBE, module, TOOLS],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [], f'{module} loaded {result.stdout.strip()}'


@pytest.mark.parametrize('package', RUNTIME_PACKAGES)
def test_no_runtime_module_names_a_tool(package):
    # Neither an import nor a module name handed to importlib or a subprocess.
    offenders = [
        f'{path.relative_to(REPO)}:{number}'
        for path in sorted((REPO / package).rglob('*.py'))
        for number, line in enumerate(path.read_text().splitlines(), start=1)
        if TOOLS in line
    ]
    assert offenders == []
