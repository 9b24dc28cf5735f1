"""Hands side by side in one run: their node ticks and the ratio to the first hand's.

``grasp-bench --compare-config PATH`` records each scenario's filtered run and replays
each hand's ticks through its own model and filter (its own warm starts), tick after tick
as its filter node runs them, in blocks of :data:`BLOCK` ticks, the hands' blocks
alternating: each block runs on the caches its own ticks keep warm, and every hand sees
the same machine load, so their ratio is measured in one run rather than across runs. A
node tick is the model terms and the filter step (``GraspModel.state`` +
``SafetyFilter.solve``), in thread CPU time and wall time.

Each node tick is also split into its parts, each with its ratio to the first hand's: the
model terms, the filter step and, within the filter step, its QP solve (the filter's
``solve_time``, wall, on the ticks that solved one). Pinocchio's calls
(:meth:`~grasp_safety_filter.model.hand.HandModel.raw_terms`, part of the model terms) are
timed after the node ticks, in blocks alternating as theirs, so that the node tick is
timed as a node runs it. A ratio of sums lies between its parts' ratios, so the node tick's
ratio comes down only with a part's.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_model import state_of
from grasp_tools.bench.recorded_run import record_filtered_run, Scenario, Tick
from grasp_tools.bench.replay import statistics

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
        model_cpu: Thread CPU time of each tick's model terms, s, shape (ticks,).
        solve: The filter's QP solve per tick (``FilterResult.solve_time``, wall; 0 on a
            tick that solved no QP), s, shape (ticks,).
        pinocchio_cpu: Thread CPU time of Pinocchio's calls at each tick's (q, dq), s,
            shape (ticks,).
    """

    label: str
    n_joints: int
    n_contacts: int
    cpu: np.ndarray
    wall: np.ndarray
    statuses: dict[str, int]
    model_cpu: np.ndarray
    solve: np.ndarray
    pinocchio_cpu: np.ndarray

    @property
    def filter_cpu(self) -> np.ndarray:
        """Thread CPU time of each tick's filter step (node tick - model terms), s."""
        return self.cpu - self.model_cpu


def pinocchio_terms(model: Any, tick: Tick) -> object:
    """Pinocchio's calls of a node tick's model terms, at the tick's (q, dq)."""
    return model.hand.raw_terms(tick.q, tick.dq)


def _blocks(n_hands: int, count: int, block: int) -> Iterator[tuple[int, range]]:
    """Yield ``(hand, its ticks)`` block after block, the hand that goes first rotating."""
    for b, start in enumerate(range(0, count, block)):
        for j in np.roll(np.arange(n_hands), -b):
            yield int(j), range(start, min(start + block, count))


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
    shape = (len(hands), count)
    cpu, wall, model_cpu = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    solve, pinocchio_cpu = np.zeros(shape), np.zeros(shape)
    statuses: list[Counter[str]] = [Counter() for _ in hands]
    clock, cpu_clock = time.perf_counter, time.thread_time
    for j, block_ticks in _blocks(len(hands), count, block):
        model, safety_filter, ticks = models[j], filters[j], hands[j][2]
        for i in block_ticks:
            tick = ticks[i]
            c0 = cpu_clock()
            t0 = clock()
            state = state_of(model, tick)
            c1 = cpu_clock()
            result = safety_filter.solve(state, tick.u_nom)
            t2 = clock()
            c2 = cpu_clock()
            cpu[j, i], wall[j, i], model_cpu[j, i] = c2 - c0, t2 - t0, c1 - c0
            solve[j, i] = result.solve_time
            statuses[j][result.status.value] += 1
    for j, block_ticks in _blocks(len(hands), count, block):
        model, ticks = models[j], hands[j][2]
        for i in block_ticks:
            c0 = cpu_clock()
            pinocchio_terms(model, ticks[i])
            pinocchio_cpu[j, i] = cpu_clock() - c0
    return [
        HandTicks(
            label,
            model.n_joints,
            model.n_contacts,
            cpu[j],
            wall[j],
            dict(statuses[j]),
            model_cpu[j],
            solve[j],
            pinocchio_cpu[j],
        )
        for j, ((label, _, _), model) in enumerate(zip(hands, models, strict=True))
    ]


def _solved_a_qp(replay: HandTicks) -> np.ndarray:
    return replay.solve[replay.solve > 0.0]


#: The node tick's parts in :func:`hand_table`: thread CPU time, the QP solve's wall time.
PARTS: dict[str, Callable[[HandTicks], np.ndarray]] = {
    'pinocchio_cpu': lambda replay: replay.pinocchio_cpu,
    'model_terms_cpu': lambda replay: replay.model_cpu,
    'filter_step_cpu': lambda replay: replay.filter_cpu,
    'qp_solve_wall': _solved_a_qp,
}


def _median_ratio(times: np.ndarray, first: np.ndarray) -> float | None:
    """Median of ``times`` over the median of ``first`` (None when either has none)."""
    if times.size == 0 or first.size == 0:
        return None
    return float(np.median(times) / np.median(first))


def hand_table(replays: Sequence[HandTicks], block: int = BLOCK) -> dict[str, Any]:
    """JSON-ready figures per hand; ``cpu_median_over_first``: its CPU median over the first's.

    ``parts_us``: the node tick's parts (:data:`PARTS`), each with its median over the first
    hand's (``over_first``; the QP solve's on the ticks that solved one, wall time).
    """
    first = replays[0]
    return {
        'block_ticks': block,
        'hands': [
            {
                'config': replay.label,
                'joints': replay.n_joints,
                'contacts': replay.n_contacts,
                'node_tick_cpu_us': statistics(replay.cpu),
                'node_tick_wall_us': statistics(replay.wall),
                'cpu_median_over_first': _median_ratio(replay.cpu, first.cpu),
                'statuses': replay.statuses,
                'parts_us': {
                    name: {
                        **statistics(times(replay)),
                        'over_first': _median_ratio(times(replay), times(first)),
                    }
                    for name, times in PARTS.items()
                },
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
            f'{_name(hand):<36}{hand["joints"]:>7}{hand["contacts"]:>9}'
            f'{cpu["median"]:>12.1f}{cpu["p99"]:>9.1f}{wall["median"]:>13.1f}'
            f'{wall["p99"]:>9.1f}{hand["cpu_median_over_first"]:>8.2f}x'
        )
    lines += [
        "its parts, median in µs (× first); Pinocchio's calls within the model terms, the "
        "filter's QP solve (wall, ticks that solved one) within the filter step:",
        f'{"config":<36}{"Pinocchio":>16}{"model terms":>16}{"filter step":>16}'
        f'{"QP solve":>16}',
    ]
    for hand in section['hands']:
        cells = [_part(hand['parts_us'][name]) for name in PARTS]
        lines.append(f'{_name(hand):<36}' + ''.join(f'{cell:>16}' for cell in cells))
    return lines


def _name(hand: dict[str, Any]) -> str:
    return Path(hand['config']).name[:35]


def _part(figures: dict[str, Any]) -> str:
    """``median (ratio×)`` of a part, or ``-`` when it has no tick."""
    if figures['median'] is None or figures['over_first'] is None:
        return '-'
    return f'{figures["median"]:.1f} ({figures["over_first"]:.2f}x)'
