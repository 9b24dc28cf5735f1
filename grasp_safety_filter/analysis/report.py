"""The printed report of a run: its summary, its generic verdict and its expected one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from grasp_safety_filter.analysis.tracking import tracking_text
from grasp_safety_filter.analysis.verdict import (
    expected_verdict,
    ExpectedVerdict,
    run_verdict,
    RunVerdict,
)
from grasp_safety_filter.io.schemas import NO_OUTCOME


def print_summary(
    mode: str, summary: dict[str, Any], out_dir: Path, expected_outcome: str = NO_OUTCOME
) -> tuple[RunVerdict, ExpectedVerdict | None]:
    """Print a run's summary, its generic verdict and, if one is declared, its expected one."""
    verdict = run_verdict(summary)
    expected = expected_verdict(expected_outcome, mode, summary)
    stop = summary['stop_reason'] or 'none'
    print(f'\n[{mode}] {out_dir}')
    print(
        f'  t_end {summary["t_end"]:.3f} s of {summary["duration_requested"]:g} s, '
        f'stop reason: {stop}'
    )
    missed = summary.get('missed_start') or {}
    if missed:
        print(
            '  recording missed the start of the run (t_0 = 0): '
            + ', '.join(f'{topic} from {t:.3f} s' for topic, t in missed.items())
        )
    for family in verdict.families:
        first = f' ({family.first_text()})' if family.violated else ''
        print(f'  {family.family:20s} {family.steps:6d} steps violated{first}')
    margins = ', '.join(
        f'{k} {v:.4g}' if v is not None else f'{k} -inf' for k, v in summary['min_margin'].items()
    )
    print(f'  smallest margins: {margins}')
    if 'object_tracking' in summary:
        print(f'  {tracking_text(summary["object_tracking"])}')
    if 'filter' in summary:
        _print_filter(summary['filter'])
    print(f'  {verdict.text()}')
    if expected is not None:
        print(f'  {expected.text}')
    return verdict, expected


def _print_filter(f: dict[str, Any]) -> None:
    relaxed = ', '.join(f'{k} {v}' for k, v in f.get('relaxed_families', {}).items())
    print(
        f'  filter: {f["steps"]} steps, {f["relaxed_steps"]} relaxed'
        f'{f" ({relaxed})" if relaxed else ""}, {f["failed_steps"]} failed, '
        f'{f.get("rejected_steps", 0)} with rejected input, '
        f'{f.get("watchdog_fallbacks", 0)} watchdog fallbacks (inputs missing during the '
        f'run; {f.get("watchdog_statuses_after_end", 0)} statuses after its end)'
    )
    timing = ', '.join(
        f'{label} {_us(f[key]["median"])} / {_us(f[key]["p99"])} us'
        for label, key in (('QP', 'qp_solve_us'), ('step', 'step_us'), ('tick', 'tick_us'))
        if key in f
    )
    print(f'  filter time (median / p99): {timing}')


def verdict_document(verdict: RunVerdict, expected: ExpectedVerdict | None) -> dict[str, Any]:
    """Return one run's entry in ``verdict.json``."""
    document = verdict.to_json()
    document['expected_outcome'] = None if expected is None else expected.outcome
    if expected is not None:
        document['reproduced'] = expected.met  # None: interrupted, not judged
        document['verdict'] = expected.text
    return document


def _us(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.0f}'
