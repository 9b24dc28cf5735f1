"""The ROS-free runner: bags a ROS user can read, analysed to the same verdict as the run."""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from grasp_safety_filter.analysis.verdict import paper_verdict
from grasp_safety_filter.cli import demo_main
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.messages import header_stamp_ns
from grasp_safety_filter.runner import analyze_bag, run, RunOptions

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
FILTERED_DURATION = 0.2
TIME_STEP = 0.001


@pytest.fixture(scope='module')
def nominal_run(tmp_path_factory):
    """Run the paper's nominal run in full (it stops on its own at about 1.2 s)."""
    return run(RunOptions(CONFIG, 'nominal'), tmp_path_factory.mktemp('nominal'))


@pytest.fixture(scope='module')
def filtered_run(tmp_path_factory):
    """Run the start of the paper's filtered run, recorded as sqlite3 (the other storage)."""
    options = RunOptions(CONFIG, 'filtered', duration=FILTERED_DURATION, storage='sqlite3')
    return run(options, tmp_path_factory.mktemp('filtered'))


def stamps(bag: Path) -> dict[str, list[int]]:
    return {
        topic: [header_stamp_ns(msg) for _, msg in messages]
        for topic, messages in read_bag(bag).items()
        if topic not in (topics.CLOCK, topics.SCENARIO)
    }


@pytest.mark.parametrize('which', ['nominal_run', 'filtered_run'])
def test_bag_has_every_topic_with_its_type_and_increasing_stamps(which, request):
    result = request.getfixturevalue(which)
    with AnyReader([result.bag]) as reader:
        recorded = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert recorded == {spec.name: spec.msgtype for spec in topics.TOPICS}
    # The paper demo has no planner, no tracker of its own (the simulator's exact odometry;
    # the ground truth beside a tracker is the hardware mode's), no ros2_control effort
    # controller and no marker node; every other topic has data.
    assert {t for t, n in counts.items() if n == 0} == {
        topics.OBJECT_REFERENCE,
        topics.OBJECT_POSE,
        topics.OBJECT_TRUE_ODOM,
        topics.EFFORT_CONTROLLER_COMMANDS,
        topics.MARKERS,
    }
    for topic, values in stamps(result.bag).items():
        assert values == sorted(values), f'{topic}: header stamps go back in time'


@pytest.mark.parametrize('which', ['nominal_run', 'filtered_run'])
def test_message_counts_match_the_run_length(which, request):
    result = request.getfixturevalue(which)
    recording = result.recording
    steps = round(recording.t_end / TIME_STEP)
    with AnyReader([result.bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    stopped_early = recording.stop_reason not in (None, 'duration')
    # A step that ends the run on a violation publishes its contacts but no next state.
    assert counts[topics.CONTACTS] == steps + (1 if stopped_early else 0)
    states = steps + 1
    for topic in (topics.JOINT_STATES, topics.OBJECT_ODOM, topics.CLOCK):
        assert counts[topic] == states, topic
    for topic in (topics.EFFORT_NOMINAL, topics.EFFORT_COMMAND, topics.MARGINS):
        assert counts[topic] == states, topic
    assert counts[topics.SCENARIO] == 1


@pytest.mark.parametrize('which', ['nominal_run', 'filtered_run'])
def test_analysis_of_the_bag_gives_the_verdict_of_the_live_run(which, request, tmp_path):
    result = request.getfixturevalue(which)
    live = result.recording.live_log
    summary, figures = analyze_bag(result.bag, tmp_path)
    assert summary['violations'] == live.violations()
    for family, margin in live.min_margin().items():
        expected = margin if np.isfinite(margin) else None
        assert summary['min_margin'][family] == expected, family
    assert summary['t_end'] == pytest.approx(result.recording.t_end, abs=1e-12)
    assert json.loads((tmp_path / 'summary.json').read_text()) == summary
    assert all(path.stat().st_size > 0 for path in figures)


def test_nominal_run_reproduces_the_papers_failure(nominal_run):
    summary = nominal_run.summary
    ok, verdict = paper_verdict('nominal', summary)
    assert ok, verdict
    assert summary['mode'] == 'nominal' and 'filter' not in summary
    assert summary['violations']['joint_limits']['first_t'] < summary['t_end']


def test_filtered_run_reports_the_filter(filtered_run):
    summary = filtered_run.summary
    assert summary['mode'] == 'filtered'
    assert summary['completed'] and summary['t_end'] == pytest.approx(FILTERED_DURATION)
    assert summary['filter']['steps'] == round(FILTERED_DURATION / TIME_STEP) + 1
    timing = summary['filter']
    for percentile in ('median', 'p99'):
        assert (
            0.0
            < timing['qp_solve_us'][percentile]
            <= timing['step_us'][percentile]
            <= timing['tick_us'][percentile]
        )
    assert sum(timing['relaxed_families'].values()) >= timing['relaxed_steps']


def test_demo_both_writes_both_runs_and_a_verdict(tmp_path):
    code = demo_main(['--mode', 'both', '--out', str(tmp_path), '--duration', '0.05'])
    for mode in ('nominal', 'filtered'):
        assert (tmp_path / mode / 'bag' / 'metadata.yaml').is_file()
        assert json.loads((tmp_path / mode / 'summary.json').read_text())['mode'] == mode
    verdict = json.loads((tmp_path / 'verdict.json').read_text())
    # 50 ms is too short for the nominal run to fail, so the paper's outcome is not shown.
    assert verdict['nominal']['reproduced'] is False
    assert code == 1


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_run_killed_mid_way_leaves_a_readable_bag_and_says_so(tmp_path, signum):
    script = (
        'import sys\n'
        'from grasp_safety_filter.cli import demo_main\n'
        f'sys.exit(demo_main(["--mode", "filtered", "--out", {str(tmp_path)!r}]))\n'
    )
    process = subprocess.Popen(
        [sys.executable, '-c', script],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
    )
    bag = tmp_path / 'bag'
    deadline = time.monotonic() + 60.0
    while not bag.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(2.0)  # let it record a while
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert 'interrupted' in stderr
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts[topics.JOINT_STATES] > 1
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['interrupted'] == signal.Signals(signum).name
    assert not summary['completed'] and summary['stop_reason'] == 'interrupted'


def test_overrides_reach_every_node_that_declares_them():
    from grasp_safety_filter.io.messages import MessageNamespace
    from grasp_safety_filter.runner import build_endpoints

    options = RunOptions(
        CONFIG,
        'filtered',
        overrides={'barrier.alpha1.gain': 10.0, 'model.friction_coefficient': 0.5},
    )
    sim, nominal, safety_filter = build_endpoints(options, MessageNamespace.from_typestore())
    assert safety_filter.filter.config.alpha1_gain == 10.0
    for endpoint in (sim, nominal, safety_filter):
        assert endpoint.model.friction_coefficient.tolist() == [0.5] * 3


@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        ({'barrier.alpha1.gian': 10.0}, "no node declares it.*did you mean 'barrier.alpha1.gain'"),
        ({'barrier.alpha1.gain': 10}, 'ROS reads 10 as an integer; write 10.0'),
        ({'barrier.alpha1.gain': -1.0}, "'barrier.alpha1.gain'.*expected > 0"),
    ],
)
def test_bad_overrides_fail_before_anything_runs(tmp_path, overrides, message):
    from grasp_safety_filter.io.parameters import ParameterError

    with pytest.raises(ParameterError, match=message):
        run(RunOptions(CONFIG, 'filtered', overrides=overrides), tmp_path)
    assert not (tmp_path / 'bag').exists()


# ----------------------------------------------------------------------------------------
# Signals at every moment of a run: a readable bag and an honest summary, or a message


def _send_sigint() -> None:
    os.kill(os.getpid(), signal.SIGINT)


def _signalling(function):
    def wrapper(*args, **kwargs):
        _send_sigint()
        return function(*args, **kwargs)

    return wrapper


# case: (moments a SIGINT is sent, bag left, summary left, the summary's "interrupted")
SIGNAL_CASES = {
    'start-up': (('build_endpoints',), False, False, None),
    'at the first state': (('first progress',), True, False, None),
    'mid-run': (('progress',), True, True, 'SIGINT'),
    'mid-run, again while closing the bag': (
        ('progress', 'set_custom_data'),
        True,
        True,
        'SIGINT',
    ),
    'mid-run, again during the analysis': (('progress', 'load_run'), True, True, 'SIGINT'),
    'during the analysis': (('load_run',), True, True, None),
    'during the figures': (('plot_run',), True, True, None),
}


@pytest.mark.parametrize('case', list(SIGNAL_CASES))
def test_a_signal_at_any_moment_leaves_a_bag_and_an_honest_summary(case, tmp_path, monkeypatch):
    from grasp_safety_filter.io.bag import BagRecorder
    import grasp_safety_filter.runner as runner

    moments, bag_left, summary_left, interrupted = SIGNAL_CASES[case]
    for name in {'build_endpoints', 'load_run', 'plot_run'} & set(moments):
        monkeypatch.setattr(runner, name, _signalling(getattr(runner, name)))
    if 'set_custom_data' in moments:
        monkeypatch.setattr(
            BagRecorder, 'set_custom_data', _signalling(BagRecorder.set_custom_data)
        )
    sent = []

    def progress(t: float, duration: float) -> None:
        first = 'first progress' in moments
        if (first or ('progress' in moments and t >= 0.005)) and not sent:
            sent.append(t)
            _send_sigint()

    with pytest.raises(runner.RunInterrupted) as caught:
        run(RunOptions(CONFIG, 'filtered', duration=0.02), tmp_path, progress)
    assert caught.value.signal == 'SIGINT'
    assert (caught.value.bag is not None) == bag_left
    assert (caught.value.summary is not None) == summary_left
    assert (tmp_path / 'summary.json').exists() == summary_left
    if bag_left:
        with AnyReader([tmp_path / 'bag']) as reader:
            assert {c.topic for c in reader.connections} >= {topics.JOINT_STATES}
    if summary_left:
        summary = json.loads((tmp_path / 'summary.json').read_text())
        assert summary.get('interrupted') == interrupted
        assert summary['completed'] == (interrupted is None)


def test_a_sigterm_before_the_first_step_is_reported_as_sigterm(tmp_path):
    """The run stops with too little for a summary; its interruption still names SIGTERM."""
    import grasp_safety_filter.runner as runner

    def progress(t: float, duration: float) -> None:
        os.kill(os.getpid(), signal.SIGTERM)

    with pytest.raises(runner.RunInterrupted) as caught:
        run(RunOptions(CONFIG, 'filtered', duration=0.02), tmp_path, progress)
    assert caught.value.signal == 'SIGTERM'
    assert caught.value.bag is not None and caught.value.summary is None


def test_a_start_up_interrupt_keeps_no_stale_claim(tmp_path, monkeypatch):
    """An earlier run's summary beside a new run's bag would describe the wrong run."""
    import grasp_safety_filter.runner as runner

    run(RunOptions(CONFIG, 'filtered', duration=0.01), tmp_path)
    monkeypatch.setattr(
        runner, 'BagRecorder', _signalling(runner.BagRecorder)
    )  # just after the earlier outputs are removed
    with pytest.raises(runner.RunInterrupted) as caught:
        run(RunOptions(CONFIG, 'filtered', duration=0.01), tmp_path)
    assert caught.value.bag is None and caught.value.summary is None
    assert not (tmp_path / 'summary.json').exists() and not (tmp_path / 'bag').exists()


@pytest.mark.parametrize('delay', [0.0, 0.3, 1.0])
def test_grasp_demo_interrupted_early_says_only_what_is_true(tmp_path, delay):
    # A signal that lands in this harness before demo_main's first line is no grasp-demo
    # output: the harness exits 130 without a word (demo_main's own handling is tested).
    script = (
        'import sys\n'
        'from grasp_safety_filter.cli import demo_main\n'
        'try:\n'
        '    print("ready", flush=True)\n'
        f'    code = demo_main(["--mode", "filtered", "--duration", "0.3", "--out", '
        f'{str(tmp_path)!r}])\n'
        'except KeyboardInterrupt:\n'
        '    code = 130\n'
        'sys.exit(code)\n'
    )
    process = subprocess.Popen(
        [sys.executable, '-c', script],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
    )
    assert process.stdout.readline() == 'ready\n'
    time.sleep(delay)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert 'Traceback' not in stderr, stderr
    summary = tmp_path / 'summary.json'
    if process.returncode != 130:  # it finished first
        assert process.returncode in (0, 1) and summary.is_file()
    elif 'the bag and summary are in' in stderr:
        assert summary.is_file() and (tmp_path / 'bag' / 'metadata.yaml').is_file()
    else:
        honest = ('no summary', 'no partial run', 'too little of the run for a summary')
        assert not stderr or any(text in stderr for text in honest), stderr
        assert not summary.exists()
