"""grasp-bench --soak: the figures it prints are those of the run it recorded."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from grasp_safety_filter.io import topics
from grasp_tools.bench import bench_main
from grasp_tools.soak import growth_per_tick, RssSample

SECONDS = 0.2
TIME_STEP = 0.001


def test_growth_is_the_slope_after_the_start_up():
    # 1 MB of start-up, then 50 bytes per tick.
    samples = [RssSample(0.0, 0.0, 100_000_000)] + [
        RssSample(t, t, 101_000_000 + round(50 * t / TIME_STEP)) for t in (1.0, 2.0, 3.0, 4.0)
    ]
    assert growth_per_tick(samples, TIME_STEP) == pytest.approx(50.0)
    assert growth_per_tick(samples[:2], TIME_STEP) is None


@pytest.fixture(scope='module')
def soak_document(tmp_path_factory):
    """Run grasp-bench --soak on a short run; return its JSON document and its table."""
    out = tmp_path_factory.mktemp('soak')
    table = io.StringIO()
    with contextlib.redirect_stdout(table):
        code = bench_main(
            [
                '--soak',
                str(SECONDS),
                '--soak-interval',
                '0.05',
                '--soak-out',
                str(out / 'run'),
                '--json',
                str(out / 'soak.json'),
            ]
        )
    assert code == 0
    return json.loads((out / 'soak.json').read_text()), table.getvalue()


def test_soak_reports_memory_bag_and_analysis_figures(soak_document):
    document, table = soak_document
    assert document['ticks'] == round(SECONDS / TIME_STEP)
    assert len(document['rss_samples']) >= 4
    assert all(s['rss_mb'] > 0 for s in document['rss_samples'])
    counts = {topic: figures['messages'] for topic, figures in document['topics'].items()}
    assert counts[topics.JOINT_STATES] == document['ticks'] + 1
    assert document['bag_mb_per_sim_second'] == pytest.approx(
        document['bag_mb'] / document['t_end']
    )
    for analysis in (document['analysis'], document['analysis_quarter']):
        assert analysis['peak_rss_mb'] > 0 and analysis['wall_s'] > 0
    assert 'RSS growth' in table and 'grasp-analyze: peak RSS' in table
    assert topics.MARGINS in table


def test_soak_refuses_a_duration_of_zero(capsys):
    with pytest.raises(SystemExit) as stopped:
        bench_main(['--soak', '0'])
    assert stopped.value.code == 2
    assert '--soak' in capsys.readouterr().err
