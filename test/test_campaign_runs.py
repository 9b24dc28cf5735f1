"""grasp-campaign end to end: the same table on local cores and on a Dask cluster.

A campaign stopped halfway (a signal, a kill, a dead worker) resumes to that table without
redoing or losing a run.
"""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from grasp_safety_filter.campaign.run import COST_COLUMNS
from grasp_safety_filter.campaign.store import read_table
from grasp_safety_filter.io.paths import config_path

CAMPAIGN = Path(sys.executable).parent / 'grasp-campaign'
RUNS = 20

# 20 short runs of the paper's hand: random friction low enough that some nominal runs slip.
CAMPAIGN_TEXT = f"""
scenario: {config_path('paper_scenario.yaml')}
duration: 0.1
modes: [nominal, filtered]
samples: 5
seed: 1
set:
  stop_on_slip: true
grid:
  barrier.alpha1.gain: [1.0, 10.0]
random:
  model.friction_coefficient: {{uniform: [0.3, 0.9]}}
reference:
  axes: [z, yaw]
  position: [0.0, 0.25]
  orientation: [0.0, 2.0]
  frequency: [0.5, 2.0]
"""


def campaign_file(tmp_path: Path) -> Path:
    path = tmp_path / 'small.yaml'
    path.write_text(CAMPAIGN_TEXT)
    return path


def command(path: Path, out: Path, *extra: str) -> list[str]:
    return [str(CAMPAIGN), str(path), '--out', str(out), '--keep-worst', '0', *extra]


def outcome_table(out: Path) -> list[dict[str, str]]:
    """Return the table without where and how long each run took."""
    return [
        {k: v for k, v in row.items() if k not in COST_COLUMNS}
        for row in read_table(out / 'runs.csv')
    ]


def assert_same_table(first: list[dict[str, str]], second: list[dict[str, str]]) -> None:
    assert len(first) == len(second) == RUNS
    for a, b in zip(first, second, strict=True):
        assert a.keys() == b.keys()
        for column in a:
            try:
                x, y = float(a[column]), float(b[column])
            except ValueError:
                assert a[column] == b[column], (column, a, b)
            else:
                assert math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12), (column, a, b)


def finished_keys(out: Path) -> list[str]:
    keys = []
    for line in (out / 'results.jsonl').read_text().splitlines():
        try:
            keys.append(json.loads(line)['key'])
        except json.JSONDecodeError:
            pass
    return keys


@pytest.fixture(scope='module')
def local_table(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp('local')
    out = tmp_path / 'out'
    result = subprocess.run(
        command(campaign_file(tmp_path), out, '--workers', '2'),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    assert len(finished_keys(out)) == RUNS
    report = (out / 'report.md').read_text()
    assert '## Held, per mode' in report
    return outcome_table(out)


def test_the_table_has_a_row_per_run_and_both_outcomes(local_table):
    assert [int(row['index']) for row in local_table] == list(range(RUNS))
    assert {row['mode'] for row in local_table} == {'nominal', 'filtered'}
    assert all(row['error'] == '' for row in local_table)
    nominal = [row for row in local_table if row['mode'] == 'nominal']
    filtered = [row for row in local_table if row['mode'] == 'filtered']
    # Low friction slips the nominal controller at once; the filter keeps these grasps.
    assert any(row['held'] == 'False' and row['first_violation'] == 'slip' for row in nominal)
    assert all(row['held'] == 'True' for row in filtered)
    # The start-up advice of the paper's scenario: cubic class-K functions freeze its joints.
    assert {row['advice'] for row in local_table} == {'frozen'}
    assert all('joint_limits' in row['advice_frozen'].split() for row in local_table)
    assert all(float(row['advice_rest_margin']) > 0.0 for row in local_table)


def test_a_dask_cluster_gives_the_same_table_through_a_dead_worker(tmp_path, local_table):
    from distributed import Client, LocalCluster

    out = tmp_path / 'out'
    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        process = subprocess.Popen(
            command(campaign_file(tmp_path), out, '--scheduler', cluster.scheduler_address),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 300
        while not (out / 'results.jsonl').is_file() or len(finished_keys(out)) < 3:
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.2)
        # A worker dies with runs in flight: the nanny restarts it, Dask reruns them.
        pids = client.run(os.getpid)
        os.kill(next(iter(pids.values())), signal.SIGKILL)
        _, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr
    assert sorted(finished_keys(out)) == sorted(set(finished_keys(out)))  # none run twice
    assert_same_table(outcome_table(out), local_table)


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGKILL])
def test_a_campaign_stopped_halfway_resumes_to_the_same_table(tmp_path, local_table, stop):
    out = tmp_path / 'out'
    path = campaign_file(tmp_path)
    process = subprocess.Popen(
        command(path, out, '--workers', '2'),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a Ctrl-C reaches the whole group, as from a terminal
    )
    deadline = time.monotonic() + 300
    while not (out / 'results.jsonl').is_file() or len(finished_keys(out)) < RUNS // 2:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.1)
    os.killpg(process.pid, stop)
    _, stderr = process.communicate(timeout=120)
    if stop == signal.SIGINT:
        assert process.returncode == 130, stderr
        assert 'the same command resumes' in stderr
    before = finished_keys(out)
    assert RUNS // 2 <= len(before) < RUNS
    result = subprocess.run(command(path, out), capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert f'({len(before)} already finished)' in result.stderr
    after = finished_keys(out)
    assert after[: len(before)] == before  # nothing lost or rewritten
    assert len(after) == len(set(after)) == RUNS  # nothing run twice
    assert_same_table(outcome_table(out), local_table)


def test_a_killed_scheduler_stops_the_campaign_and_the_same_command_resumes(
    tmp_path, local_table
):
    out = tmp_path / 'out'
    path = campaign_file(tmp_path)
    env = {**os.environ, 'DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT': '5s'}
    scheduler = subprocess.Popen(
        [sys.executable, '-m', 'distributed.cli.dask_scheduler', '--port', '0',
         '--no-dashboard', '--scheduler-file', str(tmp_path / 'scheduler.json')],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / 'scheduler.json').is_file():
            assert time.monotonic() < deadline
            time.sleep(0.1)
        time.sleep(0.5)  # the file is written whole before the scheduler listens
        address = json.loads((tmp_path / 'scheduler.json').read_text())['address']
        worker = subprocess.Popen(
            [sys.executable, '-m', 'distributed.cli.dask_worker', address, '--nthreads', '1',
             '--nworkers', '2', '--no-dashboard'],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        )  # fmt: skip
        process = subprocess.Popen(
            command(path, out, '--scheduler', address),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        deadline = time.monotonic() + 300
        while not (out / 'results.jsonl').is_file() or len(finished_keys(out)) < RUNS // 2:
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.1)
        scheduler.kill()
        _, stderr = process.communicate(timeout=120)
        worker.kill()
        worker.wait(timeout=60)
    finally:
        scheduler.kill()
    assert process.returncode == 1, stderr
    assert 'the same command resumes' in stderr
    before = finished_keys(out)
    assert RUNS // 2 <= len(before) < RUNS
    rows = [json.loads(line) for line in (out / 'results.jsonl').read_text().splitlines()]
    assert not any(row['error'] for row in rows)  # a cancelled run is no result
    result = subprocess.run(command(path, out), capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    after = finished_keys(out)
    assert after[: len(before)] == before
    assert len(after) == len(set(after)) == RUNS
    assert_same_table(outcome_table(out), local_table)
