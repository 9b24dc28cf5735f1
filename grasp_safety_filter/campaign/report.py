"""A campaign's report: success rates with intervals, per mode and per varied parameter.

``report.md`` beside ``runs.csv``, with its plots, and the worst runs of each mode recorded
again with their bags (``worst/``) for ``grasp-analyze``. Intervals are Wilson score
intervals (95 %), which stay inside [0, 1] and are honest at 0 or n successes. Runs that
raised (``error``) are counted apart: they say nothing about the filter.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import math
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.campaign.run import outcome_of
from grasp_safety_filter.campaign.spec import Campaign, RunSpec, SCENARIO_COLUMN

REPORT_FILE = 'report.md'
WORST_DIRECTORY = 'worst'
#: Distinct values up to which a varied parameter is tabulated value by value, not in bins.
MAX_LEVELS = 6
BINS = 4


def wilson_interval(held: int, runs: int, confidence: float = 0.95) -> tuple[float, float]:
    """Return the Wilson interval of a success rate ``held / runs`` (nan, nan at 0 runs)."""
    if runs == 0:
        return math.nan, math.nan
    from scipy.stats import binomtest

    interval = binomtest(held, runs).proportion_ci(confidence, method='wilson')
    return float(interval.low), float(interval.high)


def rate_text(held: int, runs: int) -> str:
    """``"97.0 % (97/100) [91.5, 99.0]"``."""
    if runs == 0:
        return '—'
    low, high = wilson_interval(held, runs)
    return f'{100 * held / runs:.1f} % ({held}/{runs}) [{100 * low:.1f}, {100 * high:.1f}]'


def _counted(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    return [row for row in rows if not row.get('error')]


def _held(rows: Sequence[Mapping[str, Any]]) -> int:
    return sum(bool(row['held']) for row in rows)


def worst_runs(
    rows: Sequence[Mapping[str, Any]], mode: str, count: int
) -> list[Mapping[str, Any]]:
    """Return the ``count`` worst finished runs of ``mode``.

    First the lost grasps, earliest violation first; then held runs, smallest friction margin
    first (the closest to slipping).
    """

    def badness(row: Mapping[str, Any]) -> tuple[bool, float, float]:
        t = row.get('first_violation_t')
        margin = row.get('min_margin.friction')
        return (
            bool(row['held']),
            math.inf if t is None else float(t),
            math.inf if margin is None else float(margin),
        )

    candidates = [row for row in _counted(rows) if row['mode'] == mode]
    return sorted(candidates, key=badness)[:count]


def record_worst(
    out_dir: Path, runs: Sequence[RunSpec], rows: Sequence[Mapping[str, Any]], count: int
) -> list[tuple[Mapping[str, Any], Path, bool]]:
    """Record the worst runs of each mode again into ``out_dir/worst/`` (bag, summary, figures).

    Returns each worst row, its directory, and whether the new run reproduced the row's
    outcome (held, first violation and its time).
    """
    from grasp_safety_filter.runner import run as run_scenario

    by_key = {run.key: run for run in runs}
    kept = []
    modes = dict.fromkeys(row['mode'] for row in rows)
    for mode in modes:
        for row in worst_runs(rows, mode, count):
            directory = out_dir / WORST_DIRECTORY / f'{row["index"]:05d}-{mode}'
            result = run_scenario(by_key[row['key']].options(), directory, force=True)
            again = outcome_of(result.summary)
            same = (
                again['held'] == row['held']
                and again['first_violation'] == row['first_violation']
                and _close(again['first_violation_t'], row['first_violation_t'])
            )
            kept.append((row, directory, same))
    return kept


def _close(first: float | None, second: float | None) -> bool:
    if first is None or second is None:
        return first is second
    return abs(first - second) < 1e-6


def write_report(
    out_dir: Path,
    campaign: Campaign,
    runs: Sequence[RunSpec],
    rows: Sequence[Mapping[str, Any]],
    worst: Sequence[tuple[Mapping[str, Any], Path, bool]] = (),
) -> Path:
    """Write ``report.md`` and its plots into ``out_dir``; return the report's path."""
    counted = _counted(rows)
    modes = [mode for mode in campaign.modes if any(row['mode'] == mode for row in rows)]
    errors = [row for row in rows if row.get('error')]
    lines = [
        f'# Campaign {campaign.path.name}',
        '',
        f'{_scenarios_text(campaign)}, {campaign.duration:g} s runs, modes '
        f'{", ".join(campaign.modes)}, {campaign.samples} samples (seed {campaign.seed}). '
        f'Finished: {len(rows)} of {len(runs)} runs; {len(errors)} raised (not counted).',
        '',
        "Held: grasp-analyze's verdict. On the rigid plant the run reached its duration "
        'with no slip, separation, joint-limit, fingertip-workspace or object-face violation; '
        'on MuJoCo with no contact lost, the object not dropped and no joint limit passed. '
        'Rates with 95 % Wilson intervals.',
        '',
        '## Held, per mode',
        '',
        '| mode | held | relaxed ticks (median, max) | first violations |',
        '| --- | --- | --- | --- |',
    ]
    for mode in modes:
        mine = [row for row in counted if row['mode'] == mode]
        relaxed = [row['relaxed_ticks'] for row in mine if row.get('relaxed_ticks') is not None]
        ticks = f'{np.median(relaxed):g}, {max(relaxed):g}' if relaxed else '—'
        firsts: dict[str, int] = {}
        for row in mine:
            if row['first_violation']:
                firsts[row['first_violation']] = firsts.get(row['first_violation'], 0) + 1
        first_text = ', '.join(f'{k} {v}' for k, v in sorted(firsts.items())) or '—'
        lines.append(f'| {mode} | {rate_text(_held(mine), len(mine))} | {ticks} | {first_text} |')
    lines += _paired(counted, campaign)
    plots = _plots(out_dir, campaign, counted, modes)
    for column, table, image in plots:
        lines += ['', f'## Held against `{column}`', '', *table, '', f'![{column}]({image})']
    lines += _worst_section(out_dir, worst)
    lines += _errors_section(errors)
    cpu = [row['cpu_s'] for row in rows if row.get('cpu_s') is not None]
    if cpu:
        lines += [
            '',
            '## Cost',
            '',
            f'CPU of the runs: {sum(cpu):.0f} s in all, median {np.median(cpu):.2f} s a run '
            f'({np.median(cpu) / campaign.duration:.2f} s per simulated second).',
        ]
    path = out_dir / REPORT_FILE
    path.write_text('\n'.join(lines) + '\n')
    return path


def _scenarios_text(campaign: Campaign) -> str:
    """``Scenario `PATH``` or, for several, how many and the first."""
    if len(campaign.scenarios) == 1:
        return f'Scenario `{campaign.scenario}`'
    return f'{len(campaign.scenarios)} scenarios (the first `{campaign.scenario}`)'


def _paired(rows: Sequence[Mapping[str, Any]], campaign: Campaign) -> list[str]:
    """Both modes on the same draw: where each held."""
    if set(campaign.modes) != {'nominal', 'filtered'}:
        return []
    outcome: dict[tuple[int, int], dict[str, bool]] = {}
    for row in rows:
        outcome.setdefault((row['cell'], row['sample']), {})[row['mode']] = bool(row['held'])
    pairs = [o for o in outcome.values() if len(o) == 2]
    if not pairs:
        return []
    count = {
        (f, n): sum(o['filtered'] == f and o['nominal'] == n for o in pairs)
        for f in (True, False)
        for n in (True, False)
    }
    return [
        '',
        f'## The same {len(pairs)} variations in both modes',
        '',
        '| | nominal held | nominal lost |',
        '| --- | --- | --- |',
        f'| filtered held | {count[True, True]} | {count[True, False]} |',
        f'| filtered lost | {count[False, True]} | {count[False, False]} |',
    ]


def _levels(values: Sequence[Any]) -> list[tuple[str, Any]]:
    """Each value, or (numbers with many values) quantile bins: ``[(label, test)]``."""
    distinct = sorted(set(values), key=str)
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in distinct)
    if len(distinct) <= MAX_LEVELS or not numeric:
        return [(_label(v), lambda x, v=v: x == v) for v in distinct]
    edges = np.quantile(np.asarray(values, dtype=float), np.linspace(0.0, 1.0, BINS + 1))
    levels = []
    for i in range(BINS):
        lo, hi = edges[i], edges[i + 1]
        last = i == BINS - 1
        test = (
            (lambda x, lo=lo, hi=hi: lo <= x <= hi)
            if last
            else (lambda x, lo=lo, hi=hi: lo <= x < hi)
        )
        levels.append((f'{lo:.3g} – {hi:.3g}', test))
    return levels


def _held_of(
    rows: Sequence[Mapping[str, Any]], mode: str, column: str, test: Callable[[Any], bool]
) -> tuple[int, int]:
    """Return how many of ``mode``'s runs whose ``column`` passes ``test`` held, of how many."""
    inside = [
        r for r in rows if r['mode'] == mode and r.get(column) is not None and test(r[column])
    ]
    return _held(inside), len(inside)


def _label(value: Any) -> str:
    return f'{value:.4g}' if isinstance(value, float) else str(value)


def _plots(
    out_dir: Path, campaign: Campaign, rows: Sequence[Mapping[str, Any]], modes: Sequence[str]
) -> list[tuple[str, list[str], str]]:
    """Per varied column: its table lines and its plot's file name."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    sections = []
    for column in campaign.varied_columns:
        values = [row[column] for row in rows if row.get(column) is not None]
        distinct = len(set(map(str, values)))
        if distinct < 2 or (column == SCENARIO_COLUMN and distinct > MAX_LEVELS):
            continue  # one value; or many scenarios, one run each: runs.csv has them
        levels = _levels(values)
        counts = {
            (label, mode): _held_of(rows, mode, column, test)
            for label, test in levels
            for mode in modes
        }
        table = [f'| `{column}` | ' + ' | '.join(modes) + ' |', '| --- |' + ' --- |' * len(modes)]
        table += [
            f'| {label} | ' + ' | '.join(rate_text(*counts[label, mode]) for mode in modes) + ' |'
            for label, _ in levels
        ]
        figure, axes = plt.subplots(figsize=(6.0, 3.2))
        for offset, mode in enumerate(modes):
            held = np.array([counts[label, mode] for label, _ in levels], dtype=float)
            with np.errstate(invalid='ignore', divide='ignore'):
                rates = held[:, 0] / held[:, 1]
            bounds = np.array([wilson_interval(int(k), int(n)) for k, n in held])
            x = np.arange(len(levels)) + 0.1 * (offset - (len(modes) - 1) / 2)
            errors = [rates - bounds[:, 0], bounds[:, 1] - rates]
            axes.errorbar(x, rates, yerr=errors, fmt='o', capsize=3, label=mode)
        axes.set_xticks(range(len(levels)), [label for label, _ in levels], fontsize=7)
        axes.set_ylim(-0.05, 1.05)
        axes.set_ylabel('held (95 % interval)')
        axes.set_xlabel(column)
        axes.legend(fontsize=8)
        figure.tight_layout()
        image = f'held_vs_{column.replace("/", "_")}.png'
        figure.savefig(out_dir / image, dpi=100)
        plt.close(figure)
        sections.append((column, table, image))
    return sections


def _worst_section(
    out_dir: Path, worst: Sequence[tuple[Mapping[str, Any], Path, bool]]
) -> list[str]:
    if not worst:
        return []
    lines = [
        '',
        '## Worst runs, recorded again',
        '',
        'Lost grasps first (earliest violation), then held runs closest to slipping. Replay: '
        '`grasp-analyze DIR/bag --out DIR/analysis`.',
        '',
        '| run | mode | held | first violation | at [s] | friction margin | directory '
        '| same outcome |',
        '| --- | --- | --- | --- | --- | --- | --- | --- |',
    ]
    for row, directory, same in worst:
        t = row['first_violation_t']
        margin = row['min_margin.friction']
        lines.append(
            f'| {row["index"]} | {row["mode"]} | {row["held"]} | {row["first_violation"] or "—"} '
            f'| {"—" if t is None else f"{t:.3f}"} | {"—" if margin is None else f"{margin:.3f}"} '
            f'| `{directory.relative_to(out_dir)}` | {"yes" if same else "NO"} |'
        )
    return lines


def _errors_section(errors: Sequence[Mapping[str, Any]]) -> list[str]:
    if not errors:
        return []
    lines = ['', '## Runs that raised', '', '| run | mode | error |', '| --- | --- | --- |']
    for row in errors[:20]:
        lines.append(f'| {row["index"]} | {row["mode"]} | {str(row["error"])[:200]} |')
    if len(errors) > 20:
        lines.append(f'| … | | {len(errors) - 20} more in runs.csv |')
    return lines
