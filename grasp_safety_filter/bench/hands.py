"""Hands side by side in one run: their node ticks and the ratio to the first hand's.

``grasp-bench --compare-config PATH`` records each scenario's filtered run and replays
each hand's ticks through its own model and filter (its own warm starts), tick after tick
as its filter node runs them, in blocks of :data:`BLOCK` ticks, the hands' blocks
alternating: each block runs on the caches its own ticks keep warm, and every hand sees
the same machine load, so their ratio is measured in one run rather than across runs. A
node tick is the model terms and the filter step (``GraspModel.state`` +
``SafetyFilter.solve``), in thread CPU time and wall time.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Any

import numpy as np

from grasp_safety_filter.bench.recorded_run import record_filtered_run, Scenario, Tick
from grasp_safety_filter.bench.replay import statistics
from grasp_safety_filter.model.grasp_model import state_of

#: Ticks of one hand replayed one after the other before the next hand's block.
BLOCK = 100


@dataclass(frozen=True, eq=False)
class HandTicks:
    """One hand's node ticks.

    Attributes:
        label: The scenario (its parameter file).
        n_joints: The hand's joints m.
        n_contacts: Its contacts n.
        cpu: Thread CPU time of each node tick, s, shape (ticks,).
        wall: Wall time of each node tick, s, shape (ticks,).
        statuses: How many ticks ended with each filter status.
    """

    label: str
    n_joints: int
    n_contacts: int
    cpu: np.ndarray
    wall: np.ndarray
    statuses: dict[str, int]


def replay_hands(
    hands: Sequence[tuple[str, Scenario, Sequence[Tick]]],
    block: int = BLOCK,
    warmup: int = 0,
) -> list[HandTicks]:
    """Replay each hand's ticks in alternating blocks (module docstring).

    Args:
        hands: Per hand, its label, scenario and recorded ticks. Each replays as many ticks
            as the hand with fewest has.
        block: Ticks of a hand replayed one after the other, >= 1.
        warmup: Each hand's first ticks, replayed once untimed before (as many).

    Raises:
        ValueError: No hand, a hand without ticks, or a block below 1.
    """
    if not hands or any(not ticks for _, _, ticks in hands):
        raise ValueError('replay_hands: expected hands with at least one tick each')
    if block < 1:
        raise ValueError(f'replay_hands: block: expected >= 1 tick, got {block}')
    count = min(len(ticks) for _, _, ticks in hands)
    filters = [scenario.safety_filter() for _, scenario, _ in hands]
    models = [scenario.model for _, scenario, _ in hands]
    for model, safety_filter, (_, _, ticks) in zip(models, filters, hands, strict=True):
        for tick in ticks[: min(warmup, count)]:
            safety_filter.solve(state_of(model, tick), tick.u_nom)
    cpu, wall = np.zeros((len(hands), count)), np.zeros((len(hands), count))
    statuses: list[Counter[str]] = [Counter() for _ in hands]
    clock, cpu_clock = time.perf_counter, time.thread_time
    for b, start in enumerate(range(0, count, block)):
        for j in np.roll(np.arange(len(hands)), -b):  # who goes first rotates
            model, safety_filter, ticks = models[j], filters[j], hands[j][2]
            for i in range(start, min(start + block, count)):
                tick = ticks[i]
                c0 = cpu_clock()
                t0 = clock()
                result = safety_filter.solve(state_of(model, tick), tick.u_nom)
                t1 = clock()
                c1 = cpu_clock()
                cpu[j, i], wall[j, i] = c1 - c0, t1 - t0
                statuses[j][result.status.value] += 1
    return [
        HandTicks(label, model.n_joints, model.n_contacts, cpu[j], wall[j], dict(statuses[j]))
        for j, ((label, _, _), model) in enumerate(zip(hands, models, strict=True))
    ]


def hand_table(replays: Sequence[HandTicks], block: int = BLOCK) -> dict[str, Any]:
    """JSON-ready figures per hand; ``cpu_median_over_first``: its CPU median over the first's."""
    first = float(np.median(replays[0].cpu))
    return {
        'block_ticks': block,
        'hands': [
            {
                'config': replay.label,
                'joints': replay.n_joints,
                'contacts': replay.n_contacts,
                'node_tick_cpu_us': statistics(replay.cpu),
                'node_tick_wall_us': statistics(replay.wall),
                'cpu_median_over_first': float(np.median(replay.cpu)) / first,
                'statuses': replay.statuses,
            }
            for replay in replays
        ],
    }


def compare_hands(
    first: tuple[str, Scenario, Sequence[Tick]],
    configs: Sequence[Path],
    duration: float,
    warmup: int,
    log: Callable[[str], None],
    overrides: tuple[dict[str, Any] | None, dict[str, Any] | None] = (None, None),
) -> dict[str, Any]:
    """Record the other scenarios' filtered runs and replay every hand (module docstring).

    Args:
        first: The benchmark's own hand: its label, scenario and replayed ticks.
        configs: The other scenarios' parameter files (their labels).
        duration: Simulated time of their recorded runs, s.
        warmup: Untimed ticks per hand before the timed ones.
        log: Called with a line saying what is being measured.
        overrides: The safety filter's and the model's parameters replaced by dotted name,
            as for the first scenario.

    Returns:
        :func:`hand_table`'s figures.
    """
    hands = [first]
    for config in configs:
        scenario = Scenario.load(config, *overrides)
        log(f'recording the filtered run of {config} ({duration:g} s simulated)')
        ticks = record_filtered_run(scenario, duration)[0]
        hands.append((str(config), scenario, ticks[: len(first[2])]))
    log(f'replaying {len(hands)} hands in alternating blocks of {BLOCK} ticks')
    return hand_table(replay_hands(hands, warmup=warmup))


def format_hands(section: dict[str, Any]) -> list[str]:
    """Return the report's lines for :func:`hand_table`'s figures."""
    lines = [
        '',
        f'hands, tick after tick in alternating blocks of {section["block_ticks"]}; '
        'node tick in µs:',
        f'{"config":<36}{"joints":>7}{"contacts":>9}{"CPU median":>12}{"p99":>9}'
        f'{"wall median":>13}{"p99":>9}{"× first":>9}',
    ]
    for hand in section['hands']:
        cpu, wall = hand['node_tick_cpu_us'], hand['node_tick_wall_us']
        lines.append(
            f'{Path(hand["config"]).name[:35]:<36}{hand["joints"]:>7}{hand["contacts"]:>9}'
            f'{cpu["median"]:>12.1f}{cpu["p99"]:>9.1f}{wall["median"]:>13.1f}'
            f'{wall["p99"]:>9.1f}{hand["cpu_median_over_first"]:>8.2f}x'
        )
    return lines
