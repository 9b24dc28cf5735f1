"""``grasp-bench-ros`` runs the graph over real DDS and prints every figure it promises."""

from __future__ import annotations

import json
import os
from pathlib import Path
import subprocess
import sys

import pytest

from grasp_tools.bench_ros import override_arguments, percentiles, report

BENCH = Path(sys.executable).parent / 'grasp-bench-ros'


def test_percentiles_of_a_known_sample():
    stats = percentiles(list(range(1, 101)))
    assert stats['median'] == pytest.approx(50.5)
    assert stats['p99'] == pytest.approx(99.01)
    assert stats['max'] == 100.0
    assert stats['count'] == 100
    assert percentiles([])['median'] is None


def test_bench_runs_the_graph_and_prints_every_figure(tmp_path):
    out = tmp_path / 'bench.json'
    result = subprocess.run(
        [str(BENCH), '--duration', '0.05', '--pings', '50', '--json', str(out)],
        env=dict(os.environ),
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    for label in (
        'baseline ping-pong round trip',
        'tick period',
        'state -> command',
        'filter latency',
        "filter node's own tick",
        'CPU per tick: safety_filter_node',
        'goal: tick period <= 3 x round trip',
        'goal: filter latency p99 <= 1 ms',
    ):
        assert label in result.stdout, label
    figures = json.loads(out.read_text(encoding='utf-8'))
    assert figures['baseline']['round_trip_ms']['count'] == 50
    graph = figures['graph']
    # 0.05 s in steps of 1 ms: the state at t = 0 and after each of the 50 steps.
    assert graph['ticks'] == 51
    assert graph['state_to_command_ms']['count'] >= 50
    # Steady statuses go out every diagnostics.period (0.1 s): the first tick's, at least.
    assert 1 <= graph['filter_tick_ms']['count'] <= graph['ticks']
    assert 0 < graph['tick_period_ms']['median'] < 1000
    assert set(graph['cpu_ms_per_tick']) == {
        'hand_sim_node',
        'nominal_controller_node',
        'safety_filter_node',
    }
    assert report(figures)  # the text is rebuilt from the JSON alone


def test_overrides_go_to_the_nodes_that_declare_them():
    arguments = override_arguments(['diagnostics.period=0.0', 'duration=3.0'])
    assert arguments['safety_filter_node'] == ['-p', 'diagnostics.period:=0.0']
    assert arguments['hand_sim_node'] == ['-p', 'duration:=3.0']
    assert arguments['nominal_controller_node'] == []
    with pytest.raises(ValueError, match=r'diagnostic\.period'):
        override_arguments(['diagnostic.period=0.0'])


def test_node_scoped_overrides_go_to_their_node_only():
    mu = 'model.friction_coefficient'
    arguments = override_arguments([f'{mu}=0.9', f'hand_sim_node/{mu}=0.5'])
    assert arguments['hand_sim_node'] == ['-p', f'{mu}:=0.5']
    assert arguments['safety_filter_node'] == ['-p', f'{mu}:=0.9']
    assert arguments['nominal_controller_node'] == ['-p', f'{mu}:=0.9']
    with pytest.raises(ValueError, match=r"unknown node 'hand_sim'"):
        override_arguments([f'hand_sim/{mu}=0.5'])
    with pytest.raises(ValueError, match=r"'hand_sim_node' does not declare 'barrier"):
        override_arguments(['hand_sim_node/barrier.alpha1.gain=1.0'])
    with pytest.raises(ValueError, match=r'no node of the graph'):
        override_arguments(['grasp_markers_node/markers.rate=1.0'])
