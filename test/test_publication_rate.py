"""How often the filter's status and margins go out, and that the counts stay exact."""

from __future__ import annotations

from pathlib import Path

import pytest

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.diagnostic_keys import Key, TickStatus
from grasp_safety_filter.nodes.publication_rate import PublicationRate, PublicationRateConfig
from grasp_safety_filter.runner import run, RunOptions

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
MS = 1_000_000  # ns

S, R, D, H = TickStatus.SOLVED, TickStatus.RELAXED, TickStatus.DISABLED, TickStatus.INPUT_HELD

#: (period s, statuses of ticks 0, 1 ms, 2 ms, ..., which ones are published).
STATUS_CASES = [
    (0.0, [S, S, S, S], [0, 1, 2, 3]),
    (0.002, [S, S, S, S, S], [0, 2, 4]),
    (0.002, [S, R, R, S, S, S], [0, 1, 2, 3, 5]),  # events each, then the change back
    (0.002, [S, S, D, D, D, S], [0, 2, 4, 5]),  # every change of status, steady ones thinned
    (0.010, [S, H, S, S, S], [0, 1, 2]),
]


@pytest.mark.parametrize(('period', 'statuses', 'published'), STATUS_CASES)
def test_steady_statuses_are_thinned_and_every_other_one_goes_out(period, statuses, published):
    rate = PublicationRate(PublicationRateConfig(diagnostics_period=period))
    sent = [k for k, status in enumerate(statuses) if rate.status_due(k * MS, status)]
    assert sent == published
    assert rate.counter_values()[Key.TICKS] == len(statuses)
    assert sum(rate.counts.values()) == len(statuses)


def test_a_forced_status_goes_out_and_margins_have_their_own_period():
    rate = PublicationRate(PublicationRateConfig(diagnostics_period=1.0, margins_period=0.003))
    assert rate.status_due(0, S) and not rate.status_due(MS, S)
    assert rate.status_due(2 * MS, S, force=True)
    assert [k for k in range(8) if rate.margins_due(k * MS)] == [0, 3, 6]


@pytest.mark.parametrize('value', [-0.1, float('nan')])
def test_a_negative_or_nan_period_is_refused_naming_the_parameter(value):
    with pytest.raises(ValueError, match=r"'diagnostics\.period'"):
        PublicationRateConfig(diagnostics_period=value)


@pytest.fixture(scope='module')
def paper_runs(tmp_path_factory):
    """Run the first 0.3 s of the filtered paper run: statuses every tick, every 0.1 s."""
    results = {}
    for period in (0.0, 0.1):
        options = RunOptions(
            CONFIG, 'filtered', duration=0.3, overrides={'diagnostics.period': period}
        )
        results[period] = run(options, tmp_path_factory.mktemp(f'period-{period}'))
    return results


def filter_statuses(bag: Path) -> int:
    return sum(
        1
        for _, msg in read_bag(bag)[topics.DIAGNOSTICS]
        for status in msg.status
        if status.name == 'safety_filter'
    )


def test_thinned_statuses_give_the_same_counts_as_every_tick(paper_runs):
    every, thinned = paper_runs[0.0], paper_runs[0.1]
    assert filter_statuses(every.bag) == 301
    assert filter_statuses(thinned.bag) < 301 / 10
    for key in ('steps', 'statuses', 'relaxed_steps', 'failed_steps', 'rejected_steps'):
        assert thinned.summary['filter'][key] == every.summary['filter'][key], key
    assert every.summary['filter']['steps'] == 301
    assert every.summary['violations'] == thinned.summary['violations']
