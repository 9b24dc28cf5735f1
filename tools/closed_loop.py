"""The closed loop over any :class:`~hand_sim_node.plant.Plant`, in one process.

Each tick: observe the plant, build our model's terms at that state (once; the nominal
controller and the filter read the same ones), compute the nominal torque u_nom for the
reference, filter it (or pass it through without a filter), and step the plant with the
result. No messages: the loop of ``grasp-demo`` without the nodes and the bag.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import time

import numpy as np

from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.control.reference import ReferenceSource
from grasp_safety_filter.control.safety_filter import SafetyFilter
from hand_sim_node.plant import Plant
from hand_sim_node.simulator import NUMERICAL_FAILURE, SimState

#: Stop reason of a loop that ran its whole duration.
DURATION = 'duration'


@dataclass(frozen=True, eq=False)
class LoopTick:
    """One control tick.

    Attributes:
        observation: The plant's state the torque was computed for.
        u_nom: The nominal controller's torque, (m,), N·m.
        u: The torque applied over the tick (u* of the filter, or u_nom), (m,), N·m.
        status: The filter's status, or None without a filter.
    """

    observation: SimState
    u_nom: np.ndarray
    u: np.ndarray
    status: FilterStatus | None


@dataclass(frozen=True, eq=False)
class LoopRun:
    """A closed-loop run.

    Attributes:
        ticks: Every tick, in order.
        final: The plant's state at the end.
        stop_reason: ``"duration"``, the plant's stop reason, or ``"numerical_failure"``
            when our model's terms could not be evaluated at the plant's state.
        wall: Wall time of the loop, s.
    """

    ticks: list[LoopTick]
    final: SimState
    stop_reason: str
    wall: float

    def array(self, name: str) -> np.ndarray:
        """Stack a tick field (``"u"``, ``"u_nom"``) or an observation field over the ticks."""
        if name in ('u', 'u_nom'):
            return np.array([getattr(tick, name) for tick in self.ticks])
        return np.array([getattr(tick.observation, name) for tick in self.ticks])


def run_closed_loop(
    plant: Plant,
    controller: NominalController,
    reference: ReferenceSource,
    safety_filter: SafetyFilter | None,
    duration: float,
    after_step: Callable[[Plant], None] | None = None,
) -> LoopRun:
    """Run plant + nominal controller (+ filter) from the plant's current state.

    Args:
        plant: The plant, at the state to start from.
        controller: The nominal controller.
        reference: Its reference (sampled at each tick's time).
        safety_filter: The filter, or None for the nominal run (u = u_nom).
        duration: Simulated time to run, s (a whole number of control periods, rounded).
        after_step: Called with the plant after every step (e.g. to record MuJoCo's
            contact report).

    Returns:
        The run; it ends early when the plant stops.
    """
    n_steps = max(1, round(duration / plant.time_step))
    ticks: list[LoopTick] = []
    stop_reason = None
    wall_start = time.perf_counter()
    for _ in range(n_steps):
        observation = plant.observe()
        try:
            state = plant.grasp_state()
        except np.linalg.LinAlgError:
            stop_reason = NUMERICAL_FAILURE
            break
        u_nom = controller.compute(state, reference.sample(observation.t)).u
        if safety_filter is None:
            u, status = u_nom, None
        else:
            result = safety_filter.solve(state, u_nom)
            u, status = result.u, result.status
        ticks.append(LoopTick(observation, u_nom, u, status))
        plant.step(u)
        if after_step is not None:
            after_step(plant)
        if plant.stop_reason is not None:
            stop_reason = plant.stop_reason
            break
    return LoopRun(
        ticks, plant.observe(), stop_reason or DURATION, time.perf_counter() - wall_start
    )
