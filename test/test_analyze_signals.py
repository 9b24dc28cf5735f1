"""``grasp-analyze`` stopped by SIGINT or SIGTERM at any moment: one line, no half file.

The analysis runs as its own process (the console script) on a short recorded run and is
signalled at seeded random moments, from its imports to its last figure. It ends with
status 130 and says in one line what it left (or, already done, it wrote every output and
says nothing), and every output file that exists is whole: summary.json parses, each PNG
ends with its IEND chunk; no temporary file is left behind and the bag is unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from grasp_safety_filter.runner import run, RunOptions

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
ANALYZE = Path(sys.executable).parent / 'grasp-analyze'
PNG_END = b'IEND\xaeB`\x82'
KILLS = 6
START = 0.3
"""Earliest signal, s: past the interpreter's own start-up, still in the tool's imports."""


@pytest.fixture(scope='module')
def bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp('run')
    run(RunOptions(CONFIG, 'filtered', duration=0.2), out)
    return out / 'bag'


def _bag_files(bag: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(bag.iterdir()) if p.is_file()}


def _check_outputs(out: Path) -> list[str]:
    names = sorted(p.name for p in out.iterdir()) if out.exists() else []
    for name in names:
        data = (out / name).read_bytes()
        if name.endswith('.json'):
            json.loads(data)
        elif name.endswith('.png'):
            assert data.endswith(PNG_END), f'{name} is cut short'
        else:
            pytest.fail(f'unexpected file left in the output: {name}')
    return names


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_at_any_moment_leaves_whole_files_and_one_line(bag, tmp_path, signum):
    before = _bag_files(bag)
    started = time.monotonic()
    subprocess.run([ANALYZE, bag, '--out', tmp_path / 'timing'], check=True, capture_output=True)
    full = time.monotonic() - started
    complete = _check_outputs(tmp_path / 'timing')
    rng = np.random.default_rng(int(signum))
    for k, delay in enumerate(rng.uniform(START, 1.1 * full, size=KILLS)):
        out = tmp_path / f'out{k}'
        child = subprocess.Popen(
            [ANALYZE, bag, '--out', out], stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        time.sleep(delay)
        child.send_signal(signum)
        _, stderr = child.communicate(timeout=120)
        text = stderr.decode()
        assert 'Traceback' not in text, text
        if child.returncode == 130:
            (line,) = text.strip().splitlines()
            assert line.startswith(f'grasp-analyze: interrupted by {signum.name}'), line
            _check_outputs(out)
        else:
            # Done before the signal, or done and then stopped by it while the interpreter
            # exited (its handlers are gone by then): all outputs written, nothing said.
            assert child.returncode in (0, -signum), (child.returncode, text)
            assert text == '', text
            assert _check_outputs(out) == complete
    assert _bag_files(bag) == before


#: When a half-built object is dropped: as the interpreter exits, or while the tool is
#: still stopping (the interrupt's traceback, which held it, let go inside the tool).
HALF_BUILT_DROPPED = {
    'at exit': ('LEFT = HalfBuilt()\n', ''),
    'while stopping': ('', '    HalfBuilt()\n'),
}


def _half_built_tool(tmp_path: Path, at_module: str, in_tool: str, stopped: bool) -> Path:
    """Write a tool that leaves an object half-built and says it was stopped, or ends with 0."""
    said, status = ('interrupted by SIGINT', 'console.INTERRUPTED') if stopped else ('done', '0')
    script = tmp_path / 'stopped.py'
    script.write_text(
        'import sys\n'
        'from grasp_safety_filter import cli, console\n'
        'class HalfBuilt:\n'
        '    def __del__(self):\n'
        '        self.expr  # never set: the interrupt came first\n'
        f'{at_module}'
        'def stopped(argv):\n'
        f'    print("grasp-analyze: {said}", file=sys.stderr)\n'
        f'{in_tool}'
        f'    return {status}\n'
        'cli.analyze_main = stopped\n'
        'sys.exit(console.analyze([]))\n'
    )
    return script


@pytest.mark.parametrize('at_module, in_tool', HALF_BUILT_DROPPED.values(), ids=HALF_BUILT_DROPPED)
def test_a_stopped_tool_says_one_line_even_if_a_half_built_object_fails_later(
    tmp_path, at_module, in_tool
):
    """An interrupt may leave a library object half-built; its __del__ fails later."""
    script = _half_built_tool(tmp_path, at_module, in_tool, stopped=True)
    result = subprocess.run([sys.executable, script], capture_output=True, text=True)
    assert result.returncode == 130
    assert result.stderr.strip().splitlines() == ['grasp-analyze: interrupted by SIGINT']


def test_a_tool_that_was_not_stopped_still_reports_a_failing_finaliser(tmp_path):
    script = _half_built_tool(tmp_path, '', HALF_BUILT_DROPPED['while stopping'][1], stopped=False)
    result = subprocess.run([sys.executable, script], capture_output=True, text=True)
    assert result.returncode == 0
    lines = result.stderr.strip().splitlines()
    assert lines[0] == 'grasp-analyze: done'
    assert lines[1].startswith('Exception ignored in: <function HalfBuilt.__del__'), lines
    assert lines[-1] == "AttributeError: 'HalfBuilt' object has no attribute 'expr'", lines
