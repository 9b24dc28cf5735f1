"""grasp-analyze streams a bag: its memory grows with the run by a few numbers a tick at most."""

from __future__ import annotations

import gc
from pathlib import Path
import tracemalloc

import numpy as np
import pytest

from grasp_safety_filter.analysis.panels import envelope
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.runner import record_run, RunOptions

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
SHORT, LONG = 0.2, 0.6  # s of the paper's filtered run
TIME_STEP = 0.001


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Record the start of the paper's filtered run twice: SHORT and 3x as long."""
    root = tmp_path_factory.mktemp('bags')
    for seconds in (SHORT, LONG):
        record_run(RunOptions(CONFIG, 'filtered', duration=seconds), root / f'{seconds}')
    return {seconds: root / f'{seconds}' for seconds in (SHORT, LONG)}


def traced_peak(bag: Path) -> int:
    """Return the Python heap's peak while a bag is read and summarised, bytes.

    The cyclic garbage collector is off meanwhile, so that what is measured is what the
    analysis holds, not when a collection happened to run.
    """
    gc.collect()
    gc.disable()
    tracemalloc.start()
    try:
        summarize(load_run(bag))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        gc.enable()


def test_analysis_memory_grows_by_at_most_a_few_numbers_per_tick(bags):
    for bag in bags.values():  # imports and first-use caches
        summarize(load_run(bag))
    short, long = traced_peak(bags[SHORT]), traced_peak(bags[LONG])
    per_tick = (long - short) / ((LONG - SHORT) / TIME_STEP)
    # Holding the messages cost 3.3 kB per tick (2.5 GB for a 120 s run); the packed
    # per-tick numbers some 400 bytes.
    assert per_tick < 1024, f'{per_tick:.0f} bytes per tick'


def test_envelope_keeps_every_extreme_in_a_bounded_number_of_points():
    t = np.arange(15_001) * TIME_STEP
    values = np.sin(2 * np.pi * t)
    values[7_777] = 5.0  # a one-tick spike (a relaxed QP)
    values[8_000:8_100] = np.nan  # a gap (a separated contact's friction)
    kept_t, kept = envelope(t, values, max_points=400)
    assert len(kept) <= 400
    assert np.all(np.diff(kept_t) > 0)
    assert np.nanmax(kept) == 5.0 and np.nanmin(kept) == np.nanmin(values)
    assert set(kept_t) <= set(t)
    short_t, short = envelope(t[:300], values[:300], max_points=400)
    assert np.array_equal(short_t, t[:300]) and np.array_equal(short, values[:300])
