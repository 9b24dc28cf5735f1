"""A campaign's throughput and overhead: ``python -m grasp_tools.bench.campaign FILE --out DIR``.

The campaign's pending runs are split into ``--blocks`` consecutive blocks, run through
``grasp-campaign``'s engine on one local cluster of ``--workers`` processes (resuming from
``DIR`` like the command). Before each block and after the last, ``--serial`` of the
campaign's runs (a seeded random sample, the same each time) are timed one after the other in
this process: one run's rate, measured next to each block, so that a shared machine's drift
over a long campaign moves both sides of each block's ratio alike. Prints each block's rate
against ``workers x`` the mean of its two bracketing serial rates, their median and range,
the whole campaign's, and the overhead: the CPU of every process of the campaign (this one
with the scheduler, the workers) beyond the runs' own, as a share of the runs' CPU. Then
writes ``runs.csv`` and ``report.md`` as the command does.
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
    parser.add_argument('--serial', type=int, default=6, help='runs timed one by one')
    parser.add_argument('--blocks', type=int, default=5, help='blocks between serial timings')
    args = parser.parse_args(argv)
    campaign = load_campaign(args.campaign)
    runs = campaign.runs()
    execute_run(runs[0])  # imports and compiled kernels, as a worker's first run
    picks = np.random.default_rng(0).choice(len(runs), min(args.serial, len(runs)), replace=False)
    sample = [runs[i] for i in sorted(picks)]  # both modes, short and long runs, as the campaign
    store = ResultStore(args.out)
    pending_runs = [run for run in runs if run.key not in store.finished]
    pending = {run.key for run in pending_runs}
    blocks = [list(b) for b in np.array_split(np.arange(len(pending_runs)), args.blocks) if len(b)]
    me = psutil.Process()
    serial = [len(sample) / _serial(sample)]
    done, elapsed, cpu_all, ratios = 0, 0.0, 0.0, []
    with dask_client(workers=args.workers) as client:
        for block in blocks:
            cpu_before = _tree_cpu(me)
            started = time.perf_counter()
            block_done = execute([pending_runs[i] for i in block], store, client)
            block_elapsed = time.perf_counter() - started
            cpu_all += _tree_cpu(me) - cpu_before  # the workers still alive: their CPU counts
            serial.append(len(sample) / _serial(sample))
            done, elapsed = done + block_done, elapsed + block_elapsed
            one_run = 0.5 * (serial[-2] + serial[-1])
            ratios.append(block_done / block_elapsed / (args.workers * one_run))
            print(
                f'block {len(ratios)}: {block_done} runs in {block_elapsed:.1f} s, '
                f'{block_done / block_elapsed:.3f} runs/s; one run at a time {serial[-2]:.3f} '
                f'-> {serial[-1]:.3f} runs/s; ratio {ratios[-1]:.2f}',
                flush=True,
            )
    serial_rate = float(np.mean(serial))
    print(
        f'one run at a time ({len(sample)} runs, {len(serial)} times): '
        f'{min(serial):.3f}-{max(serial):.3f} runs/s, mean {serial_rate:.3f}'
    )
    rows = store.rows(runs)
    run_cpu = sum(row['cpu_s'] for row in rows if row['key'] in pending and row.get('cpu_s'))
    if done:
        rate = done / elapsed
        print(
            f'campaign: {done} runs in {elapsed:.1f} s: {rate:.3f} runs/s = '
            f"{rate / (args.workers * serial_rate):.2f} x {args.workers} x one run's mean rate; "
            f'per block {np.median(ratios):.2f} median, {min(ratios):.2f}-{max(ratios):.2f}'
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
