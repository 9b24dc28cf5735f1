"""The plant interface: what a closed loop needs from a hand–object simulation.

A plant is reset to a state, stepped one control period with a joint torque held over it,
and observed; the observation is what ``hand_sim_node`` publishes (joint states, object
pose and twist), a :class:`~hand_sim_node.simulator.SimState`. Two plants implement it:

- :class:`RigidPlant`: our own model (:class:`~hand_sim_node.simulator.Simulator`: rigid,
  exactly rolling contacts that cannot slip or separate);
- :class:`~hand_sim_node.mujoco_plant.MuJoCoPlant`: MuJoCo (soft contacts, Coulomb
  friction), from the optional ``mujoco`` package.

:func:`make_plant` builds either by name.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import rotation_matrix
from hand_sim_node.config import SimConfig
from hand_sim_node.simulator import SimState, Simulator, StepReport

#: The observation of a plant: time, joint angles and rates, object pose and twist (palm frame).
Observation = SimState

#: The plants :func:`make_plant` knows.
PLANTS = ('rigid', 'mujoco')


@runtime_checkable
class Plant(Protocol):
    """A hand–object plant stepped at a fixed control period.

    Attributes:
        model: The grasp model the plant was built from (the controller's and filter's).
        time_step: The control period: one :meth:`step`, s.
    """

    model: GraspModel
    time_step: float

    @property
    def step_index(self) -> int:
        """Number of steps since the last :meth:`reset`."""

    @property
    def stop_reason(self) -> str | None:
        """Why the plant cannot be stepped any more, or None."""

    def reset(self, state: Observation | None = None) -> Observation:
        """Restart from ``state`` (None: the configured initial grasp, at rest)."""

    def step(self, effort: np.ndarray) -> Observation:
        """Advance one control period with the joint torque ``effort`` (m,), N·m, held."""

    def observe(self) -> Observation:
        """Return the current state."""

    def grasp_state(self) -> GraspState:
        """Our model's terms at the current state (computed once per state)."""


def initial_state(model: GraspModel, config: SimConfig) -> Observation:
    """Return the configured initial grasp at rest, the joints projected onto exact contact.

    The same state :meth:`Simulator.reset` starts from.
    """
    R_object_to_palm = rotation_matrix(config.initial_object_orientation)
    q = model.project_to_contact(
        config.initial_joint_positions, config.initial_object_position, R_object_to_palm
    )
    return SimState(
        0.0,
        q,
        np.zeros(model.n_joints),
        config.initial_object_position,
        config.initial_object_orientation,
        np.zeros(6),
    )


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
    def step_index(self) -> int:
        """Number of steps since the last reset."""
        return self.simulator.step_index

    @property
    def stop_reason(self) -> str | None:
        """The simulator's stop reason."""
        return self.simulator.stop_reason

    def reset(self, state: Observation | None = None) -> Observation:
        """Restart the simulator from ``state`` (None: the initial grasp)."""
        self.last_report = None
        return self.simulator.reset(state)

    def step(self, effort: np.ndarray) -> Observation:
        """One simulator step; the model terms already built are its first stage."""
        self.last_report = self.simulator.step(effort)
        return self.simulator.state

    def observe(self) -> Observation:
        """Return the simulator's state."""
        return self.simulator.state

    def grasp_state(self) -> GraspState:
        """Return the simulator's own model terms (the ones its next step reuses)."""
        return self.simulator.grasp_state()


def make_plant(kind: str, model: GraspModel, config: SimConfig, **options: object) -> Plant:
    """Build the plant ``kind`` (``"rigid"`` or ``"mujoco"``) at its initial grasp.

    Args:
        kind: One of :data:`PLANTS`.
        model: The grasp model.
        config: The simulator's configuration.
        **options: Keyword arguments of :class:`~hand_sim_node.mujoco_plant.MuJoCoPlant`
            (none for the rigid plant).

    Raises:
        ConfigError: An unknown plant, options for the rigid plant, or the MuJoCo plant
            without the ``mujoco`` package.
    """
    if kind == 'rigid':
        if options:
            raise ConfigError(f'plant "rigid": takes no options, got {sorted(options)}')
        return RigidPlant(model, config)
    if kind == 'mujoco':
        from hand_sim_node.mujoco_plant import MuJoCoPlant

        return MuJoCoPlant(model, config, **options)
    raise ConfigError(f'plant: expected one of {list(PLANTS)}, got {kind!r}')
