"""``grasp-demo --mode both --jobs 2``: the runs side by side, the same outputs as one by one."""

from __future__ import annotations

import contextlib
import io
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest
from rosbags.highlevel import AnyReader

from grasp_safety_filter.cli import demo_main
import grasp_safety_filter.demo_runs as demo_runs
from grasp_safety_filter.io import topics

REPO = Path(__file__).resolve().parent.parent
DURATION = '0.05'


def _grasp_demo(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Run the console script ``grasp-demo`` (its signal handling included)."""
    script = 'import sys\nfrom grasp_safety_filter.console import demo\nsys.exit(demo())\n'
    return subprocess.run(
        [sys.executable, '-c', script, '--out', str(out), *args],
        capture_output=True,
        text=True,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
        timeout=600,
    )


def _recorded(bag: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message as recorded; diagnostics without their measured times (``*_us``)."""
    with AnyReader([bag]) as reader:
        messages: dict[str, list[tuple[int, object]]] = {}
        for connection, stamp, data in reader.messages():
            content: object = bytes(data)
            if connection.topic == topics.DIAGNOSTICS:
                content = [
                    (
                        s.level,
                        s.name,
                        s.message,
                        [(v.key, v.value) for v in s.values if not v.key.endswith('_us')],
                    )
                    for s in reader.deserialize(data, connection.msgtype).status
                ]
            messages.setdefault(connection.topic, []).append((stamp, content))
    return messages


def _untimed(summary: dict) -> dict:
    """Drop the filter's measured times (``*_us``) from a summary: they vary run to run."""
    if 'filter' in summary:
        summary['filter'] = {k: v for k, v in summary['filter'].items() if not k.endswith('_us')}
    return summary


def _shown(text: str, out: Path) -> list[str]:
    """Return the printed lines without the output directory and measured filter times."""
    return [
        line.replace(str(out), 'OUT') for line in text.splitlines() if 'filter time' not in line
    ]


def test_side_by_side_gives_what_one_after_the_other_gives(tmp_path):
    done = {
        jobs: _grasp_demo(
            tmp_path / jobs, '--mode', 'both', '--duration', DURATION, '--jobs', jobs
        )
        for jobs in ('1', '2')
    }
    one, two = done['1'], done['2']
    # 50 ms is too short for the nominal run to show the paper's outcome: exit code 1.
    assert one.returncode == two.returncode == 1, two.stderr
    assert _shown(one.stdout, tmp_path / '1') == _shown(two.stdout, tmp_path / '2')
    assert one.stderr == two.stderr == ''
    assert (tmp_path / '1' / 'verdict.json').read_text() == (
        tmp_path / '2' / 'verdict.json'
    ).read_text()
    for mode in ('nominal', 'filtered'):
        first, second = tmp_path / '1' / mode, tmp_path / '2' / mode
        assert _recorded(first / 'bag') == _recorded(second / 'bag')
        assert _untimed(json.loads((first / 'summary.json').read_text())) == _untimed(
            json.loads((second / 'summary.json').read_text())
        )
        figures = sorted(p.name for p in first.glob('*.png'))
        assert figures == sorted(p.name for p in second.glob('*.png')) and figures
        for name in figures:
            assert (first / name).read_bytes() == (second / name).read_bytes(), name


def _demo_both(out: Path) -> tuple[int, str, str]:
    printed, errors = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(errors):
        code = demo_main(
            ['--mode', 'both', '--duration', '0.02', '--jobs', '2', '--out', str(out)]
        )
    return code, printed.getvalue(), errors.getvalue()


def _failing_nominal(failure):
    """``runner.run`` whose nominal run ends in ``failure()`` (in the forked child)."""
    real_run = demo_runs.run

    def run(options, out_dir, progress=None, force=False):
        if options.mode == 'nominal':
            failure()
        return real_run(options, out_dir, progress, force=force)

    return run


def _raise() -> None:
    raise ValueError('a failure in the nominal run')


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


@pytest.mark.parametrize(
    ('failure', 'said'),
    [(_raise, 'ValueError: a failure in the nominal run'), (_die, 'killed by SIGKILL')],
)
def test_a_child_that_fails_or_dies_is_a_failed_run(failure, said, tmp_path, monkeypatch):
    monkeypatch.setattr(demo_runs, 'run', _failing_nominal(failure))
    code, printed, errors = _demo_both(tmp_path)
    assert code == 1
    assert '[nominal] the run failed in its own process' in errors and said in errors, errors
    assert printed == ''  # reported in order: the failed first run ends the report
    assert not (tmp_path / 'verdict.json').exists()
    assert (tmp_path / 'filtered' / 'summary.json').is_file()


def test_no_fork_runs_them_one_after_the_other(tmp_path, monkeypatch):
    import grasp_safety_filter.analysis.forked as forked

    def no_fork(method):
        raise ValueError(f'cannot find context for {method!r}')

    monkeypatch.setattr(forked.multiprocessing, 'get_context', no_fork)
    code, printed, errors = _demo_both(tmp_path)
    assert 'no second process' in errors and 'one after the other' in errors
    assert code == 1  # 20 ms: the nominal run does not show the paper's outcome
    assert printed.index('[nominal]') < printed.index('[filtered]')
    assert set(json.loads((tmp_path / 'verdict.json').read_text())) == {'nominal', 'filtered'}


@pytest.mark.parametrize(
    ('signum', 'whole_group'), [(signal.SIGINT, True), (signal.SIGTERM, False)]
)
def test_a_signal_during_both_runs_stops_both_with_readable_bags(tmp_path, signum, whole_group):
    """Ctrl-C reaches the process group; SIGTERM only grasp-demo, which stops its child."""
    script = 'import sys\nfrom grasp_safety_filter.console import demo\nsys.exit(demo())\n'
    process = subprocess.Popen(
        [sys.executable, '-c', script, '--mode', 'both', '--jobs', '2', '--out', str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
        start_new_session=True,
    )
    bags = [tmp_path / mode / 'bag' for mode in ('nominal', 'filtered')]
    deadline = time.monotonic() + 120.0
    while not all(b.exists() for b in bags) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # both recording
    if whole_group:
        os.killpg(process.pid, signum)
    else:
        process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=180)
    assert process.returncode == 130, stderr
    assert 'Traceback' not in stderr and 'SystemError' not in stderr, stderr
    assert f'[filtered] interrupted by {signum.name}' in stderr, stderr
    with pytest.raises(ProcessLookupError):
        os.killpg(process.pid, 0)  # no process of the group is left
    for bag in bags:
        with AnyReader([bag]) as reader:
            assert {c.topic for c in reader.connections} >= {topics.JOINT_STATES}
    nominal = tmp_path / 'nominal' / 'summary.json'
    if '[nominal] interrupted' in stderr:
        assert f'[nominal] interrupted by {signum.name}' in stderr
        assert stdout.find('[nominal]') == -1
    else:  # it completed before the signal
        assert '[nominal]' in stdout and not json.loads(nominal.read_text()).get('interrupted')
    assert not (tmp_path / 'verdict.json').exists()


def _signalled_inside_a_run_block() -> str:
    """Signal a child that leaves signals to its parent inside a run's block (none raises)."""
    from grasp_safety_filter.io.interrupts import interrupt_on_signals

    with interrupt_on_signals():
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.raise_signal(signum)
        time.sleep(0.05)
        return signal.getsignal(signal.SIGINT) is signal.SIG_IGN and 'ignored'


def test_the_child_ignores_sigint_and_sigterm_even_inside_a_run():
    """A handler raising inside numba's loading of a kernel gave SystemError: none runs."""
    from grasp_safety_filter.analysis.forked import ForkedCall

    with ForkedCall(_signalled_inside_a_run_block, leave_signals=True) as child:
        assert child.result() == 'ignored'
