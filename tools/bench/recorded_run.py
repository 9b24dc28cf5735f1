"""The paper's scenario, its recorded filtered run, and the closed loops' real-time factors."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
import tempfile
import time
from typing import Any

import numpy as np

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import Pose, ReferenceSource
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_tools.bench.node_callbacks import FilterCallbackTimes
from grasp_tools.closed_loop import LoopRun, run_closed_loop
from hand_sim_node.config import SimConfig
from hand_sim_node.plant import Plant, RigidPlant
from hand_sim_node.simulator import SimState, Simulator


@dataclass(frozen=True)
class Scenario:
    """The paper's scenario as the three nodes read it from one parameter file.

    Attributes:
        config: The parameter file.
        model: The grasp model (the nodes each build their own; they are identical).
        sim_config: The simulator's configuration.
        nominal_config: The nominal controller's gains and reference.
        filter_config: The safety filter's configuration.
    """

    config: Path
    model: GraspModel
    sim_config: SimConfig
    nominal_config: NominalConfig
    filter_config: SafetyFilterConfig

    @classmethod
    def load(
        cls,
        config: Path,
        filter_overrides: dict[str, Any] | None = None,
        plant_overrides: dict[str, Any] | None = None,
    ) -> Scenario:
        """Read the scenario; the overrides replace parameters by dotted name.

        ``filter_overrides``: the safety filter's; ``plant_overrides``: the simulator's
        (``hand_sim_node``'s, ``model.*`` among them: the one model every part reads).

        Raises:
            ParameterError: A bad parameter file or override value, or a plant override
                that ``hand_sim_node`` does not declare.
            ValueError: A filter override names no safety-filter parameter.
        """
        known = SafetyFilterConfig().to_parameters()
        unknown = sorted(set(filter_overrides or {}) - set(known))
        if unknown:
            raise ValueError(
                f'filter override {unknown[0]!r}: expected one of {", ".join(sorted(known))}'
            )
        sim_params = load_node_parameters(config, HAND_SIM_NODE, overrides=plant_overrides)
        filter_params = dict(load_node_parameters(config, SAFETY_FILTER_NODE))
        filter_params.update(filter_overrides or {})
        return cls(
            config=Path(config),
            model=GraspModel.from_parameters(sim_params),
            sim_config=SimConfig.from_parameters(sim_params),
            nominal_config=NominalConfig.from_parameters(
                load_node_parameters(config, NOMINAL_CONTROLLER_NODE)
            ),
            filter_config=SafetyFilterConfig.from_parameters(filter_params),
        )

    def safety_filter(self) -> SafetyFilter:
        """Build a fresh filter (no warm start)."""
        return SafetyFilter.from_config(self.model, self.filter_config)

    def reference(self, start: Tick | SimState | SimState) -> ReferenceSource:
        """Build the nominal controller's reference, started at ``start``'s pose and time."""
        return self.nominal_config.make_reference(
            Pose(start.p_object_in_palm, start.R_object_to_palm), start.t
        )

    def run_on(
        self,
        plant: Plant,
        filtered: bool,
        duration: float,
        after_step: Callable[[Plant], None] | None = None,
    ) -> LoopRun:
        """Run the scenario's closed loop on ``plant`` from its current state.

        The nominal controller, its reference started at the plant's pose, and a fresh
        filter when ``filtered`` (else u = u_nom); ``after_step`` as in
        :func:`~grasp_tools.closed_loop.run_closed_loop`.
        """
        return run_closed_loop(
            plant,
            NominalController(self.nominal_config),
            self.reference(plant.observe()),
            self.safety_filter() if filtered else None,
            duration,
            after_step,
        )


@dataclass(frozen=True, eq=False)
class Tick:
    """One control tick of the recorded run: the plant state, u_nom and the filter's u*."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray
    u_nom: np.ndarray
    u: np.ndarray
    status: FilterStatus


@dataclass(frozen=True)
class LoopRate:
    """A closed loop's speed.

    Attributes:
        simulated: Simulated time covered, s.
        wall: Wall time spent, s.
        steps: Simulator steps.
        stop_reason: Why the run ended (``"duration"`` when it ran to the end).
    """

    simulated: float
    wall: float
    steps: int
    stop_reason: str

    @classmethod
    def of(cls, simulator: Simulator, wall: float) -> LoopRate:
        """Return the rate of a loop that ran ``simulator`` from its start in ``wall`` s."""
        return cls(simulator.t, wall, simulator.step_index, simulator.stop_reason or 'duration')

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second (> 1: faster than real time)."""
        return self.simulated / self.wall if self.wall > 0.0 else float('inf')

    def to_json(self) -> dict[str, Any]:
        """Return the figures as a JSON object."""
        return {
            'simulated_s': self.simulated,
            'wall_s': self.wall,
            'steps': self.steps,
            'stop_reason': self.stop_reason,
            'real_time_factor': self.real_time_factor,
        }


def _closed_loop(
    scenario: Scenario, duration: float
) -> tuple[Simulator, NominalController, ReferenceSource, int]:
    """Build a closed loop's simulator (at the scenario's start), controller and reference.

    Returns:
        Them and the number of steps ``duration`` takes.
    """
    simulator = Simulator(scenario.model, scenario.sim_config)
    controller = NominalController(scenario.nominal_config)
    n_steps = max(1, round(duration / scenario.sim_config.time_step))
    return simulator, controller, scenario.reference(simulator.state), n_steps


def record_filtered_run(
    scenario: Scenario, duration: float
) -> tuple[list[Tick], LoopRate, np.ndarray, np.ndarray]:
    """Run simulator + nominal controller + filter closed loop and keep every tick.

    The controller and the filter read the simulator's own model terms of each state
    (:meth:`Simulator.grasp_state`), which its step then reuses as the first stage, as a
    process that runs plant and filter together would.

    Returns:
        The ticks, the loop's rate (its wall time includes the bookkeeping of the ticks,
        a few µs each), and the simulator step's wall time and thread CPU time per tick, s.
    """
    simulator, controller, reference, n_steps = _closed_loop(scenario, duration)
    safety_filter = scenario.safety_filter()
    ticks: list[Tick] = []
    step_times: list[float] = []
    step_cpu_times: list[float] = []
    wall_start = time.perf_counter()
    while simulator.stop_reason is None and simulator.step_index < n_steps:
        s = simulator.state
        # The simulator's own model terms: its first Runge–Kutta stage reuses them.
        state = simulator.grasp_state()
        u_nom = controller.compute(state, reference.sample(s.t)).u
        result = safety_filter.solve(state, u_nom)
        ticks.append(
            Tick(
                s.t,
                s.q,
                s.dq,
                s.p_object_in_palm,
                s.R_object_to_palm,
                s.twist_object,
                u_nom,
                result.u,
                result.status,
            )
        )
        # The CPU clock is read outside the wall-clock interval it brackets.
        cpu_start = time.thread_time()
        step_start = time.perf_counter()
        simulator.step(result.u)
        step_times.append(time.perf_counter() - step_start)
        step_cpu_times.append(time.thread_time() - cpu_start)
    rate = LoopRate.of(simulator, time.perf_counter() - wall_start)
    return ticks, rate, np.array(step_times), np.array(step_cpu_times)


def nominal_loop_rate(scenario: Scenario, duration: float) -> LoopRate:
    """Real-time factor of simulator + nominal controller (the paper's unfiltered run).

    The closed loop of :func:`grasp_tools.closed_loop.run_closed_loop` on the rigid plant.
    """
    plant = RigidPlant(scenario.model, scenario.sim_config)
    loop = scenario.run_on(plant, filtered=False, duration=duration)
    return LoopRate.of(plant.simulator, loop.wall)


def runner_loop_rate(
    config: Path,
    duration: float,
    time_step: float,
    overrides: dict[str, Any] | None = None,
    callback_times: FilterCallbackTimes | None = None,
) -> LoopRate:
    """Real-time factor of the ROS-free runner's filtered run, recording every message to a bag.

    ``overrides`` replace parameters of every node that declares them, as ``grasp-demo --set``.
    ``callback_times``: times the safety filter's callbacks in the same run (the wall time
    then includes its two clock reads per callback).

    Times :func:`grasp_safety_filter.runner.record_run` (the loop and the bag, not the
    analysis and figures :func:`~grasp_safety_filter.runner.run` adds afterwards).
    """
    from grasp_safety_filter.runner import record_run, RunOptions

    with tempfile.TemporaryDirectory(prefix='grasp-bench-') as directory:
        options = RunOptions(
            config, mode='filtered', duration=duration, overrides=dict(overrides or {})
        )
        wall_start = time.perf_counter()
        recording = record_run(
            options,
            Path(directory) / 'bag',
            wrap_filter_callback=None if callback_times is None else callback_times.wrap,
        )
        wall = time.perf_counter() - wall_start
    steps = round(recording.t_end / time_step)
    return LoopRate(recording.t_end, wall, steps, recording.stop_reason or 'duration')
