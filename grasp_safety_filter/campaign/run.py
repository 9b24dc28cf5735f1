"""One campaign run, on whichever worker it lands: run it, and reduce it to one table row.

The run is the lockstep runner's (the same stream ``grasp-demo`` records), recorded to a bag
in a temporary directory that is removed once the bag is summarised: a worker needs no shared
disk, and a campaign of thousands of runs keeps no bags (its worst runs are recorded again by
the report, which the lockstep makes the same run).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import socket
import tempfile
import time
import traceback
from typing import Any

from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.analysis.verdict import run_verdict
from grasp_safety_filter.campaign.spec import RunSpec
from grasp_safety_filter.control.startup_advice import StartupAdvice
from grasp_safety_filter.model_report import scenario_advice
from grasp_safety_filter.runner import record_run

#: The outcome columns of a row, after the run's identity and what was varied.
OUTCOME_COLUMNS = (
    'held',
    'completed',
    't_end',
    'stop_reason',
    'first_violation',
    'first_violation_t',
    'violated',
    'min_margin.fingertip_workspace',
    'min_margin.joint_limits',
    'min_margin.friction',
    'relaxed_ticks',
    'failed_ticks',
    'ticks',
    'position_error_rms',
    'orientation_error_rms',
    'max_slip',
    'advice',
    'advice_frozen',
    'advice_rest_margin',
    'advice_still_acceleration',
    'error',
)
#: Where and how long it ran: not part of the outcome (differ between machines and runs).
COST_COLUMNS = ('cpu_s', 'wall_s', 'worker')


def execute_run(run: RunSpec) -> dict[str, Any]:
    """Run ``run`` and return its row; a run that raises is a row with its ``error``.

    ``cpu_s`` is the CPU time of the thread that ran it (the run is single-threaded).
    """
    start_cpu, start_wall = time.thread_time(), time.perf_counter()
    try:
        options = run.options()
        advice = scenario_advice(options.config, options.overrides)
        with tempfile.TemporaryDirectory(prefix='grasp-campaign-') as directory:
            bag = Path(directory) / 'bag'
            record_run(options, bag)
            outcome = {**outcome_of(summarize(load_run(bag))), **advice_columns(advice)}
    except Exception as error:  # recorded in its row: one failing run does not stop the others
        outcome = failed_outcome(f'{type(error).__name__}: {error}', traceback.format_exc())
    return {
        **identity(run),
        **outcome,
        'cpu_s': time.thread_time() - start_cpu,
        'wall_s': time.perf_counter() - start_wall,
        'worker': f'{socket.gethostname()}:{os.getpid()}',
    }


def identity(run: RunSpec) -> dict[str, Any]:
    """Return the row's first columns: which run, in which mode, with what varied."""
    return {
        'index': run.index,
        'key': run.key,
        'mode': run.mode,
        'sample': run.sample,
        'cell': run.cell,
        **run.varied,
    }


def failed_outcome(error: str, details: str = '') -> dict[str, Any]:
    """Return the outcome of a run that did not finish (it raised, or its worker died)."""
    outcome: dict[str, Any] = dict.fromkeys(OUTCOME_COLUMNS)
    outcome['error'] = error
    if details:
        outcome['traceback'] = details
    return outcome


def outcome_of(summary: dict[str, Any]) -> dict[str, Any]:
    """Return a run's outcome columns from its ``summary.json``.

    ``held`` is ``grasp-analyze``'s verdict (:func:`~grasp_safety_filter.analysis.verdict.
    run_verdict`): on the rigid plant, the run reached its duration with no constraint
    violated (slip, separation, a joint limit, the fingertip workspace, an object face),
    whatever the scenario stops on; on MuJoCo, with no contact lost, the object not dropped
    and no joint limit passed (its slip is measured: ``max_slip``).
    """
    firsts = {
        family: record['first_t']
        for family, record in summary['violations'].items()
        if record['count'] > 0
    }
    first = min(firsts, key=firsts.__getitem__) if firsts else None
    margins = summary['min_margin']
    steps = summary.get('filter', {})
    tracking = summary.get('object_tracking', {})
    events = summary.get('contact_events') or {}
    slips = [d for d in (events.get('slip_distance') or {}).values() if d is not None]
    return {
        'held': run_verdict(summary).held,
        'completed': bool(summary['completed']),
        't_end': summary['t_end'],
        'stop_reason': summary['stop_reason'] or '',
        'first_violation': first or '',
        'first_violation_t': firsts[first] if first else None,
        'violated': ' '.join(sorted(firsts)),
        **{  # the summary's margins are finite or None
            f'min_margin.{family}': margins.get(family)
            for family in ('fingertip_workspace', 'joint_limits', 'friction')
        },
        'relaxed_ticks': steps.get('relaxed_steps'),
        'failed_ticks': steps.get('failed_steps'),
        'ticks': steps.get('steps'),
        'position_error_rms': _rms(tracking, 'position_error_m'),
        'orientation_error_rms': _rms(tracking, 'orientation_error_rad'),
        'max_slip': max(slips) if slips else None,
        'error': '',
    }


def advice_columns(advice: StartupAdvice) -> dict[str, Any]:
    """Return the filter's start-up advice at the run's initial grasp as row columns.

    ``advice``: its verdict (``ok``, ``frozen``, ``moving``, ``infeasible`` or
    ``undetermined``); ``advice_frozen``: the frozen families; ``advice_rest_margin``: the QP's
    torque margin at rest, N·m; ``advice_still_acceleration``: the largest joint
    acceleration of the torque that accelerates the grasp least at rest, rad/s^2 (each None
    when not finite).
    """
    return {
        'advice': advice.verdict,
        'advice_frozen': ' '.join(advice.frozen),
        'advice_rest_margin': _finite(advice.rest_margin),
        'advice_still_acceleration': _finite(advice.still_acceleration),
    }


def _rms(tracking: dict[str, Any], key: str) -> float | None:
    return _finite((tracking.get(key) or {}).get('rms'))


def _finite(value: Any) -> float | None:
    if value is None or not math.isfinite(float(value)):
        return None
    return float(value)
