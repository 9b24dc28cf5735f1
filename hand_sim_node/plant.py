"""The plant interface: what a closed loop needs from a hand–object simulation.

A plant is reset to a state, stepped one control period with a joint torque held over it,
and observed; the observation is what ``hand_sim_node`` publishes (joint states, object
pose and twist), a :class:`~hand_sim_node.simulator.SimState`. After each step a plant
also gives a :class:`~hand_sim_node.simulator.StepReport` of it (our model's terms at the
start of the step, the contact forces in our contact frames, the constraint margins and
events the simulator node publishes and logs) and, if it measures real contacts, a
:class:`ContactReport`. Two plants implement it:

- :class:`RigidPlant`: our own model (:class:`~hand_sim_node.simulator.Simulator`: rigid,
  exactly rolling contacts that cannot slip or separate);
- :class:`~hand_sim_node.mujoco_plant.MuJoCoPlant`: MuJoCo (soft contacts, Coulomb
  friction), from the optional ``mujoco`` package.

:class:`PlantConfig` (from ``hand_sim_node``'s ``plant`` and ``mujoco.*`` parameters)
builds either.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.parameters import flatten_parameters
from grasp_safety_filter.io.plant_schema import MUJOCO_PLANT, PLANTS, RIGID_PLANT
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from hand_sim_node.config import SimConfig
from hand_sim_node.event_log import EventLog
from hand_sim_node.mjcf import MjcfOptions
from hand_sim_node.simulator import SimState, Simulator, StepReport

__all__ = ['PLANTS', 'ContactReport', 'Plant', 'PlantConfig', 'RigidPlant']


@dataclass(frozen=True, eq=False)
class ContactReport:
    """What a plant with real contacts measures at every contact, arrays in contact order (n,).

    Attributes:
        t: Time, s.
        present: The fingertip touches the object: a normal force, or a distance up to the
            touch tolerance.
        distance: Signed distance fingertip sphere–object, m (< 0: interpenetration).
        normal_force: Normal contact force, N (≥ 0; 0 without contact).
        tangential_force: Magnitude of the friction force, N.
        slip_speed: Tangential speed of the fingertip's material point relative to the
            object's at the contact point, m/s (0 without contact).
        slip_distance: Slip speed integrated since the reset, m.
        object_dropped: No fingertip touches the object, or it fell below a set height.
    """

    t: float
    present: np.ndarray
    distance: np.ndarray
    normal_force: np.ndarray
    tangential_force: np.ndarray
    slip_speed: np.ndarray
    slip_distance: np.ndarray
    object_dropped: bool


@dataclass(frozen=True)
class PlantConfig:
    """Which plant ``hand_sim_node`` simulates, and MuJoCo's options.

    Attributes:
        kind: One of :data:`PLANTS`.
        mujoco: MuJoCo's contact and integration parameters (used by the MuJoCo plant only).
    """

    kind: str = RIGID_PLANT
    mujoco: MjcfOptions = field(default_factory=MjcfOptions)

    def __post_init__(self) -> None:
        if self.kind not in PLANTS:
            raise ConfigError(
                f"parameter 'plant': expected one of {list(PLANTS)}, got {self.kind!r}"
            )

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> PlantConfig:
        """Build from ``hand_sim_node``'s ``plant`` and ``mujoco.*`` parameters."""
        flat = flatten_parameters(params)
        return cls(str(flat.get('plant', RIGID_PLANT)), MjcfOptions.from_parameters(flat))

    def build(self, model: GraspModel, config: SimConfig) -> Plant:
        """Build this plant for ``model`` at ``config``'s initial grasp.

        Raises:
            MuJoCoUnavailableError: The MuJoCo plant without the ``mujoco`` package.
        """
        if self.kind == MUJOCO_PLANT:
            from hand_sim_node.mujoco_plant import MuJoCoPlant

            return MuJoCoPlant(model, config, self.mujoco)
        return RigidPlant(model, config)


@runtime_checkable
class Plant(Protocol):
    """A hand–object plant stepped at a fixed control period.

    Attributes:
        model: The grasp model the plant was built from (the controller's and filter's).
        time_step: The control period: one :meth:`step`, s.
        config: The simulator configuration it was built with (stop rules the plant
            honours may be changed between steps).
        last_report: The last step's report (None before the first step after a reset).
        log: The constraint margins and events of every step since the reset.
    """

    model: GraspModel
    time_step: float
    config: SimConfig
    last_report: StepReport | None
    log: EventLog

    @property
    def step_index(self) -> int:
        """Number of steps since the last :meth:`reset`."""

    @property
    def stop_reason(self) -> str | None:
        """Why the plant cannot be stepped any more, or None."""

    def reset(self, state: SimState | None = None) -> SimState:
        """Restart from ``state`` (None: the configured initial grasp, at rest)."""

    def step(self, effort: np.ndarray) -> SimState:
        """Advance one control period with the joint torque ``effort`` (m,), N·m, held."""

    def observe(self) -> SimState:
        """Return the current state."""

    def grasp_state(self) -> GraspState:
        """Our model's terms at the current state (computed once per state)."""

    def contact_report(self) -> ContactReport | None:
        """Return what the plant measures at the real contacts now; None: none (rigid)."""


class RigidPlant:
    """Our rigid rolling-contact model as a :class:`Plant` (a thin wrapper of the Simulator).

    Args:
        model: The grasp model.
        config: The simulator's configuration (``time_step`` is the control period).

    Attributes:
        simulator: The wrapped simulator.
        last_report: The last step's :class:`StepReport` (contact forces, margins, events).
    """

    def __init__(self, model: GraspModel, config: SimConfig) -> None:
        self.model = model
        self.time_step = config.time_step
        self.simulator = Simulator(model, config)
        self.last_report: StepReport | None = None

    @property
    def config(self) -> SimConfig:
        """The simulator's configuration (its stop rules and gains apply from the next step)."""
        return self.simulator.config

    @config.setter
    def config(self, config: SimConfig) -> None:
        self.simulator.config = config

    @property
    def log(self) -> EventLog:
        """The simulator's constraint record since the reset."""
        return self.simulator.log

    @property
    def step_index(self) -> int:
        """Number of steps since the last reset."""
        return self.simulator.step_index

    @property
    def stop_reason(self) -> str | None:
        """The simulator's stop reason."""
        return self.simulator.stop_reason

    def reset(self, state: SimState | None = None) -> SimState:
        """Restart the simulator from ``state`` (None: the initial grasp)."""
        self.last_report = None
        return self.simulator.reset(state)

    def step(self, effort: np.ndarray) -> SimState:
        """One simulator step; the model terms already built are its first stage."""
        self.last_report = self.simulator.step(effort)
        return self.simulator.state

    def observe(self) -> SimState:
        """Return the simulator's state."""
        return self.simulator.state

    def grasp_state(self) -> GraspState:
        """Return the simulator's own model terms (the ones its next step reuses)."""
        return self.simulator.grasp_state()

    def contact_report(self) -> None:
        """None: rigid contacts cannot be lost or slip (slip is only β > μ, an event)."""
        return None
