"""``grasp-campaign FILE --out DIR``: a campaign's runs, their table and its report.

Run again with the same ``--out``, it resumes: finished runs are read from
``DIR/results.jsonl`` and only the others run. Exit status 0 when every run finished
(whatever they held), 130 when stopped by a signal, 1 when the scheduler was not reached or
was lost, 2 for an invalid campaign file.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import shutil
import sys
import time
from typing import Any

from grasp_safety_filter.campaign.spec import Campaign, CampaignError, load_campaign
from grasp_safety_filter.campaign.store import CAMPAIGN_COPY, RESULTS_FILE, ResultStore, TABLE_FILE
from grasp_safety_filter.errors import config_error_line, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.interrupts import signal_name

PROG = 'grasp-campaign'
INTERRUPTED = 130


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('campaign', type=Path, help='campaign file (YAML), e.g. config/campaigns/')
    parser.add_argument('--out', type=Path, required=True, help='results directory (resumed)')
    parser.add_argument(
        '--scheduler',
        metavar='ADDRESS',
        help='a Dask scheduler, e.g. tcp://head:8786 (default: a local cluster of --workers)',
    )
    parser.add_argument(
        '--workers', type=int, default=None, help='local worker processes (default: one per core)'
    )
    parser.add_argument(
        '--keep-worst',
        type=int,
        default=3,
        metavar='K',
        help='record the K worst runs of each mode again, with bags and figures (default 3)',
    )
    parser.add_argument(
        '--retry-errors', action='store_true', help='run again the runs that raised'
    )
    return parser


def _check_out_dir(out_dir: Path) -> None:
    """Accept a results directory that is new, empty, or a campaign's (with ``results.jsonl``)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise CampaignError(f"--out '{out_dir}': not a directory")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / RESULTS_FILE).is_file():
        raise CampaignError(
            f"--out '{out_dir}': holds files but no {RESULTS_FILE}: not a campaign's directory"
        )


def _check_runs(campaign: Campaign) -> None:
    """Build the first run of every grid cell: a bad combination fails here, not in a run."""
    from rosbags.typesys import get_typestore, Stores

    from grasp_safety_filter.io.messages import MessageNamespace
    from grasp_safety_filter.runner import build_endpoints

    msgs = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
    seen: set[int] = set()
    for run in campaign.runs():
        if run.cell not in seen:
            seen.add(run.cell)
            build_endpoints(run.options(), msgs)


def main(argv: list[str] | None = None) -> int:
    """Run a campaign (module docstring)."""
    args = _parser().parse_args(argv)
    try:
        campaign = load_campaign(args.campaign)
        _check_out_dir(args.out)
        _check_runs(campaign)
    except (CampaignError, ValueError) as error:
        print(config_error_line(PROG, error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    runs = campaign.runs()
    args.out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(args.campaign, args.out / CAMPAIGN_COPY)
    store = ResultStore(args.out)
    if args.retry_errors:
        store.finished = {k: row for k, row in store.finished.items() if not row.get('error')}
    status = _execute(campaign, runs, store, args)
    rows = store.rows(runs)
    _finish(args.out, campaign, runs, rows, args.keep_worst if status == 0 else 0)
    return status


def _execute(campaign: Campaign, runs: list[Any], store: ResultStore, args: Any) -> int:
    from tqdm import tqdm

    from grasp_safety_filter.campaign.engine import dask_client, execute
    from grasp_safety_filter.io.interrupts import interrupt_on_signals

    keys = {run.key for run in runs}
    already = sum(key in store.finished for key in keys)
    print(
        f'{PROG}: {len(runs)} runs of {campaign.duration:g} s ({already} already finished) '
        f'into {args.out}',
        file=sys.stderr,
    )
    start = time.perf_counter()
    # On a terminal the bar moves; in a batch job's log it is a line every 30 s.
    interval = 0.5 if sys.stderr.isatty() else 30.0
    with tqdm(
        total=len(keys), initial=already, unit='run', mininterval=interval, file=sys.stderr
    ) as bar:
        lost = [0, 0]

        def progress(row: dict[str, Any]) -> None:
            lost[0] += bool(row.get('error'))
            lost[1] += not row.get('held') and not row.get('error')
            bar.set_postfix_str(f'lost {lost[1]}, raised {lost[0]}', refresh=False)
            bar.update()

        try:
            with interrupt_on_signals(), dask_client(args.scheduler, args.workers) as client:
                done = execute(runs, store, client, progress)
        except KeyboardInterrupt as interrupt:
            bar.close()
            print(
                f'{PROG}: interrupted by {signal_name(interrupt)}: {len(store.rows(runs))} of '
                f'{len(runs)} runs finished, kept in {args.out / RESULTS_FILE}; the same '
                'command resumes',
                file=sys.stderr,
            )
            return INTERRUPTED
        except OSError as error:  # the scheduler cannot be reached or was lost
            bar.close()
            print(
                f'{PROG}: the scheduler was not reached or was lost ({error}): '
                f'{len(store.rows(runs))} of {len(runs)} runs finished; the same command resumes',
                file=sys.stderr,
            )
            return 1
    elapsed = time.perf_counter() - start
    print(
        f'{PROG}: {done} runs in {elapsed:.1f} s ({done / elapsed if elapsed else 0:.2f} runs/s)',
        file=sys.stderr,
    )
    return 0


def _finish(
    out_dir: Path, campaign: Campaign, runs: list[Any], rows: list[Any], keep: int
) -> None:
    from grasp_safety_filter.campaign.report import record_worst, write_report
    from grasp_safety_filter.campaign.store import table_columns, write_table

    write_table(out_dir / TABLE_FILE, table_columns(campaign), rows)
    worst = record_worst(out_dir, runs, rows, keep) if keep > 0 else []
    report = write_report(out_dir, campaign, runs, rows, worst)
    print(f'{PROG}: {out_dir / TABLE_FILE}, {report}', file=sys.stderr)
