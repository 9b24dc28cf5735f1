"""A campaign's throughput and overhead: ``python -m grasp_tools.bench.campaign FILE --out DIR``.

Times ``--serial`` of the campaign's runs, a seeded random sample, one after the other in this
process (after one to warm up), before and again after the campaign: one run's rate, its
drift on a shared machine bracketed. Between them, the whole campaign runs through
``grasp-campaign``'s engine on a local cluster of ``--workers`` processes, resuming from
``DIR`` like the command. Prints the campaign's rate against ``workers x`` one run's rate,
and the overhead: the CPU of every process of the campaign (this one with the scheduler,
the workers) beyond the runs' own, as a share of the runs' CPU. Then writes ``runs.csv``
and ``report.md`` as the command does.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np
import psutil

from grasp_safety_filter.campaign.command import _finish
from grasp_safety_filter.campaign.engine import dask_client, default_workers, execute
from grasp_safety_filter.campaign.run import execute_run
from grasp_safety_filter.campaign.spec import load_campaign
from grasp_safety_filter.campaign.store import ResultStore


def _tree_cpu(process: psutil.Process) -> float:
    """User + system CPU of a process and its living descendants, s."""
    total = 0.0
    for member in [process, *process.children(recursive=True)]:
        try:
            times = member.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += times.user + times.system
    return total


def _serial(runs: list[Any]) -> float:
    """Run ``runs`` one after the other; return their total wall time, s."""
    return sum(execute_run(run)['wall_s'] for run in runs)


def main(argv: list[str] | None = None) -> int:
    """Measure and print (module docstring)."""
    parser = argparse.ArgumentParser(prog='python -m grasp_tools.bench.campaign')
    parser.add_argument('campaign', type=Path)
    parser.add_argument('--out', type=Path, required=True)
    parser.add_argument('--workers', type=int, default=default_workers())
    parser.add_argument('--serial', type=int, default=10, help='runs timed one by one')
    args = parser.parse_args(argv)
    campaign = load_campaign(args.campaign)
    runs = campaign.runs()
    execute_run(runs[0])  # imports and compiled kernels, as a worker's first run
    picks = np.random.default_rng(0).choice(len(runs), min(args.serial, len(runs)), replace=False)
    sample = [runs[i] for i in sorted(picks)]  # both modes, short and long runs, as the campaign
    before = _serial(sample)
    store = ResultStore(args.out)
    pending = {run.key for run in runs} - set(store.finished)
    me = psutil.Process()
    cpu_before = _tree_cpu(me)
    start = time.perf_counter()
    with dask_client(workers=args.workers) as client:
        started = time.perf_counter()
        done = execute(runs, store, client)
        elapsed = time.perf_counter() - started
        cpu_all = _tree_cpu(me) - cpu_before  # the workers still alive: their CPU counts
    total = time.perf_counter() - start
    after = _serial(sample)
    serial_rate = 2 * len(sample) / (before + after)
    print(
        f'one run at a time ({len(sample)} runs): {len(sample) / before:.3f} runs/s before the '
        f'campaign, {len(sample) / after:.3f} after; {serial_rate:.3f} in all'
    )
    rows = store.rows(runs)
    run_cpu = sum(row['cpu_s'] for row in rows if row['key'] in pending and row.get('cpu_s'))
    if done:
        rate = done / elapsed
        print(
            f"campaign: {done} runs in {elapsed:.1f} s ({total:.1f} s with the cluster's start "
            f'and stop): {rate:.3f} runs/s = {rate / (args.workers * serial_rate):.2f} x '
            f"{args.workers} x one run's rate"
        )
        busy = sum(row['wall_s'] for row in rows if row['key'] in pending) / (
            args.workers * elapsed
        )
        print(f'workers busy running runs {100 * busy:.1f} % of the time')
        print(
            f'CPU: runs {run_cpu:.1f} s, every process {cpu_all:.1f} s: overhead '
            f"{100 * (cpu_all - run_cpu) / run_cpu:.1f} % of the runs' CPU"
        )
    print(f'finished: {len(rows)} of {len(runs)} runs')
    _finish(args.out, campaign, runs, rows, keep=3)
    return 0


if __name__ == '__main__':
    sys.exit(main())
