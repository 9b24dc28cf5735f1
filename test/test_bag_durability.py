"""Bags survive SIGKILL: what reached the disk is recovered, and little is lost.

A child process writes a bag and reports, after each tick, the stamp it has written up to
(an unbuffered write to a file, which a SIGKILL does not undo). The test kills it with
SIGKILL at a random point, recovers the bag and checks that its messages are exactly a
prefix of what an uninterrupted writer writes, ending at most ``LOSS_BOUND_NS`` before the
child's last reported tick.

Two children: a synthetic writer (the runner's topics, fast, so that kills fall anywhere,
chunk and commit boundaries included), and the runner itself (a real paper run, whose
recovered bag ``grasp-analyze`` must analyse).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
import yaml

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import bag_topics, BagReadError, BagRecorder
from grasp_safety_filter.io.bag_recovery import recover_bag, STAGING_DIRECTORY
from grasp_safety_filter.io.bag_storage import FLUSH_PERIOD_NS
from grasp_safety_filter.io.interrupts import interrupt_on_signals

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
DT_NS = 1_000_000
LOSS_BOUND_NS = 100_000_000
"""Most a kill may cost: 0.1 s of stamps before the child's last tick."""
SYNTHETIC_TICKS = 2000
RUNNER_DURATION = 0.25
KILLS = 3
SEED = 20261202
CHILD_TIMEOUT = 60.0
REPORT = struct.Struct('<q')


def synthetic_ticks(typestore, ticks: int):
    """Yield each tick's ``(topic, stamp_ns, cdr)`` records, as a lockstep runner writes them.

    Every table topic of type JointState or Clock, each tick, with values of its own (about
    the runner's 7 kB per tick), and the scenario once, first.
    """
    types = typestore.types
    by_type = {spec.msgtype: [] for spec in topics.TOPICS}
    for spec in topics.TOPICS:
        by_type[spec.msgtype].append(spec.name)
    rows = [f'row{i}' for i in range(40)]
    for k in range(ticks):
        stamp = types['builtin_interfaces/msg/Time'](sec=k // 1000, nanosec=k % 1000 * DT_NS)
        header = types['std_msgs/msg/Header'](stamp=stamp, frame_id='')
        records = [(topics.SCENARIO, types['std_msgs/msg/String'](data='{}'))] * (k == 0)
        records += [(name, types['rosgraph_msgs/msg/Clock'](clock=stamp))
                    for name in by_type['rosgraph_msgs/msg/Clock']]
        for i, name in enumerate(by_type['sensor_msgs/msg/JointState']):
            values = np.arange(len(rows), dtype=np.float64) * (i + 1) + k
            state = types['sensor_msgs/msg/JointState'](
                header=header, name=rows, position=values, velocity=-values, effort=values / 2
            )
            records.append((name, state))
        yield [
            (topic, k * DT_NS, bytes(typestore.serialize_cdr(msg, msg.__msgtype__)))
            for topic, msg in records
        ]


def _child(kind: str, storage: str, bag: str, report: str) -> None:
    """Write a bag as ``kind`` does, reporting each written tick's stamp to ``report``."""
    fd = os.open(report, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    if kind == 'runner':
        from grasp_safety_filter.runner import record_run, RunOptions

        def progress(t: float, duration: float) -> None:
            os.write(fd, REPORT.pack(round(t * 1e9)))

        options = RunOptions(CONFIG, 'nominal', duration=RUNNER_DURATION, storage=storage)
        record_run(options, Path(bag), progress=progress)
        return
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with interrupt_on_signals(), BagRecorder(bag, storage, typestore=typestore) as recorder:
        for tick in synthetic_ticks(typestore, SYNTHETIC_TICKS):
            for topic, stamp, data in tick:
                recorder.write_cdr(topic, stamp, data)
            os.write(fd, REPORT.pack(tick[0][1]))


def reported(report: Path) -> list[int]:
    data = report.read_bytes() if report.exists() else b''
    return [value for (value,) in REPORT.iter_unpack(data[: len(data) // 8 * 8])]


def kill_at(kind: str, storage: str, bag: Path, target_ns: int, delay: float) -> int:
    """Start a writer child, SIGKILL it once it reports ``target_ns`` (+ ``delay`` s).

    Returns:
        The last stamp the child reported.

    """
    report = bag.parent / f'{bag.name}.report'
    child = subprocess.Popen(
        [sys.executable, __file__, kind, storage, str(bag), str(report)],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + CHILD_TIMEOUT
        while not (stamps := reported(report)) or stamps[-1] < target_ns:
            assert child.poll() is None, f'child ended before the kill: {child.stderr.read()}'
            assert time.monotonic() < deadline, 'child too slow'
            time.sleep(0.002)
        time.sleep(delay)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL
    return reported(report)[-1]


def bag_records(bag: Path) -> list[tuple[str, int, bytes]]:
    with AnyReader([bag]) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def recover(bag: Path, capsys) -> str:
    """``grasp-analyze --recover``: one line on stdout saying what it recovered."""
    from grasp_safety_filter.cli import analyze_main

    assert not (bag / 'metadata.yaml').exists()
    assert analyze_main([str(bag), '--recover']) == 0
    captured = capsys.readouterr()
    assert captured.err == ''
    (line,) = captured.out.splitlines()
    assert line.startswith(f'grasp-analyze: {bag}: incomplete bag (no metadata.yaml'), line
    # The bag itself says so too.
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())
    custom = metadata['rosbag2_bagfile_information']['custom_data']
    assert custom == {'recovered': line.split(f'{bag}: ', 1)[1]}
    return line


def check_prefix(recovered, reference, last_tick_ns: int, line: str) -> None:
    """``recovered`` is a prefix of ``reference`` ending at most LOSS_BOUND_NS early."""
    assert recovered == reference[: len(recovered)]
    last = recovered[-1][1] if recovered else -DT_NS
    assert last <= last_tick_ns + DT_NS  # the child may have begun its next tick
    assert last_tick_ns - last <= LOSS_BOUND_NS, (last_tick_ns, last)
    assert f' {len(recovered)} messages' in line
    if recovered:
        assert f'to stamp {last / 1e9:.3f} s' in line


@pytest.fixture(scope='module')
def synthetic_reference() -> list[tuple[str, int, bytes]]:
    typestore = get_typestore(Stores.ROS2_JAZZY)
    return [r for tick in synthetic_ticks(typestore, SYNTHETIC_TICKS) for r in tick]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_sigkill_at_random_points_loses_at_most_the_bound(
    storage, synthetic_reference, tmp_path, capsys
):
    rng = np.random.default_rng([SEED, len(storage)])
    for i in range(KILLS):
        bag = tmp_path / f'bag{i}'
        target = int(rng.integers(0, (SYNTHETIC_TICKS * 3) // 4)) * DT_NS
        last_tick = kill_at('synthetic', storage, bag, target, float(rng.uniform(0, 0.005)))
        line = recover(bag, capsys)
        check_prefix(bag_records(bag), synthetic_reference, last_tick, line)
        # Recovering again finds the bag complete.
        assert recover_bag(bag) is None


@pytest.fixture(scope='module')
def runner_reference(tmp_path_factory) -> list[tuple[str, int, bytes]]:
    from grasp_safety_filter.runner import record_run, RunOptions

    bag = tmp_path_factory.mktemp('reference') / 'bag'
    record_run(RunOptions(CONFIG, 'nominal', duration=RUNNER_DURATION), bag)
    return bag_records(bag)


def comparable(records):
    """Return the records without the filter's timings (diagnostics carry solve times)."""
    return [(t, s, b'' if t == topics.DIAGNOSTICS else d) for t, s, d in records]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_killed_paper_run_is_recovered_and_analysed(
    storage, runner_reference, tmp_path, capsys
):
    from grasp_safety_filter.cli import analyze_main

    rng = np.random.default_rng([SEED, 7, len(storage)])
    bag = tmp_path / 'bag'
    target = int(rng.integers(80, 200)) * DT_NS
    last_tick = kill_at('runner', storage, bag, target, float(rng.uniform(0, 0.005)))
    out = tmp_path / 'analysis'
    assert analyze_main([str(bag), '--out', str(out)]) == 0
    captured = capsys.readouterr()
    assert 'Traceback' not in captured.err
    line = captured.out.splitlines()[0]
    assert line.startswith(f'grasp-analyze: {bag}: incomplete bag (no metadata.yaml'), line
    recovered = bag_records(bag)
    check_prefix(comparable(recovered), comparable(runner_reference), last_tick, line)
    summary = json.loads((out / 'summary.json').read_text())
    assert not summary['completed']
    assert summary['t_end'] == pytest.approx(recovered[-1][1] / 1e9, abs=2e-3)


def write_synthetic(bag: Path, storage: str, ticks: int) -> list[tuple[str, int, bytes]]:
    """Write ``ticks`` synthetic ticks to a closed bag; return its records in write order."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    records = [r for tick in synthetic_ticks(typestore, ticks) for r in tick]
    with BagRecorder(bag, storage, typestore=typestore) as recorder:
        for topic, stamp, data in records:
            recorder.write_cdr(topic, stamp, data)
    return records


@pytest.mark.parametrize('damage', ['cut', 'zeroed'])
def test_an_unfinished_mcap_file_gives_up_only_its_damaged_tail(damage, tmp_path):
    """What a kill in the middle of a write, or a power loss, leaves: a cut or zeroed tail.

    Every chunk wholly before the damage is recovered, nothing after it.
    """
    source = tmp_path / 'source'
    ticks = 400  # 8 chunks
    records = write_synthetic(source, 'mcap', ticks)
    (data,) = source.glob('*.mcap')
    content = data.read_bytes()
    rng = np.random.default_rng([SEED, len(damage)])
    for i, cut in enumerate(sorted(rng.integers(0, len(content), 6))):
        bag = tmp_path / f'bag{i}'
        bag.mkdir()
        tail = b'' if damage == 'cut' else bytes(len(content) - cut)
        (bag / data.name).write_bytes(content[:cut] + tail)
        with pytest.raises(BagReadError, match=f'no metadata.yaml.* --recover {bag}`'):
            bag_topics(bag)
        recovery = recover_bag(bag)
        assert recovery is not None
        recovered = bag_records(bag)
        assert recovered == records[: len(recovered)]
        assert recovery.messages == len(recovered)
        # Chunks of about equal size end every FLUSH_PERIOD_NS: only the damaged one is lost
        # (twice that allows for the estimated stamp at the cut).
        kept = recovered[-1][1] if recovered else -DT_NS
        assert recovery.dropped_bytes <= len(content) - cut + 2**20
        stamp_at_cut = cut / len(content) * ticks * DT_NS
        assert stamp_at_cut - kept <= 2 * FLUSH_PERIOD_NS + DT_NS


def test_a_bag_still_being_written_is_not_recovered(tmp_path, capsys):
    from grasp_safety_filter.cli import analyze_main

    typestore = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / 'bag'
    with BagRecorder(bag, 'mcap', typestore=typestore) as recorder:
        for tick in synthetic_ticks(typestore, 120):
            for topic, stamp, data in tick:
                recorder.write_cdr(topic, stamp, data)
        files = sorted(p.name for p in bag.iterdir())
        assert analyze_main([str(bag)]) == 2
        captured = capsys.readouterr()
        assert captured.err == (
            f'grasp-analyze: {bag}: cannot recover: {bag / files[0]} is still open for '
            'writing by another process (still recording?)\n'
        )
        assert sorted(p.name for p in bag.iterdir()) == files  # untouched
    assert recover_bag(bag) is None  # closed: complete


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_an_interrupted_recovery_is_redone(storage, tmp_path):
    """A recovery killed half-way leaves the original file; the next one starts afresh."""
    bag = tmp_path / 'bag'
    records = write_synthetic(bag, storage, 120)
    (bag / 'metadata.yaml').unlink()
    (bag / STAGING_DIRECTORY / 'bag').mkdir(parents=True)
    (bag / STAGING_DIRECTORY / 'bag' / 'bag.mcap').write_bytes(b'half written')
    recovery = recover_bag(bag)
    assert recovery.problem == 'no metadata.yaml'
    assert recovery.messages == len(records)
    assert bag_records(bag) == records
    suffix = 'mcap' if storage == 'mcap' else 'db3'
    assert sorted(p.name for p in bag.iterdir()) == [f'bag.{suffix}', 'metadata.yaml']


if __name__ == '__main__':
    _child(*sys.argv[1:])
