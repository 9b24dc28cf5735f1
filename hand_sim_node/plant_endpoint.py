"""What both simulator endpoints share: one run of a plant, its contact events and its end.

The lockstep endpoint (:class:`~hand_sim_node.endpoint.HandSimEndpoint`) and the hardware
mode's (:class:`~hand_sim_node.hardware.HardwareEndpoint`) derive from
:class:`PlantEndpoint`. It builds the plant, the ``/grasp/scenario`` text and, for a plant
with real contacts, the run's contact event record; it says whether the run is over and
why, steps the plant keeping the torque it applied (for ``/hand/joint_states``), builds the
contact-event and end-of-run ``hand_sim`` statuses (:mod:`hand_sim_node.sim_status`) and
takes new live parameters (:data:`LIVE_FIELDS`). How the statuses are stamped and
published is each endpoint's own.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from grasp_safety_filter.io.messages import DiagnosticReport, MessageNamespace
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.scenario import scenario_document, scenario_to_text
from hand_sim_node.config import SimConfig
from hand_sim_node.contact_events import ContactEventTracker
from hand_sim_node.plant import Plant, PlantConfig
from hand_sim_node.sim_status import contact_event_report, DURATION, end_of_run_report
from hand_sim_node.simulator import StepReport

#: SimConfig fields that may change while the simulator runs (the others are read-only).
LIVE_FIELDS = (
    'stop_on_slip',
    'stop_on_workspace_exit',
    'position_gain',
    'velocity_gain',
    'command_timeout',
)


class PlantEndpoint:
    """A run of a plant as both simulator endpoints see it (module docstring).

    Args:
        model: The grasp model of the hand and object.
        sim_config: Initial state, integrator, ``time_step``, ``duration``, stop rules.
        msgs: Message classes to build (rclpy or rosbags).
        scenario_text: The ``/grasp/scenario`` JSON; default: built from ``model`` and
            ``sim_config`` (:func:`grasp_safety_filter.nodes.scenario.scenario_document`).
        plant_config: The plant to simulate (default: the rigid one).

    Attributes:
        plant: The plant.
    """

    def __init__(
        self,
        model: GraspModel,
        sim_config: SimConfig,
        msgs: MessageNamespace,
        scenario_text: str | None = None,
        plant_config: PlantConfig | None = None,
    ) -> None:
        self.model = model
        self.msgs = msgs
        self.plant_config = plant_config or PlantConfig()
        self.plant: Plant = self.plant_config.build(model, sim_config)
        self.scenario_text = (
            scenario_text
            if scenario_text is not None
            else scenario_to_text(scenario_document(model, sim_config))
        )
        self._contact_events = (
            None
            if self.plant.contact_report() is None
            else ContactEventTracker(self.plant_config.kind, model.contact_names)
        )
        self._started = False
        self._reset_run()

    def _reset_run(self) -> None:
        """Forget the run so far (the plant itself is reset by the caller)."""
        self._applied_effort = np.zeros(self.model.n_joints)
        self._reported_end = False
        if self._contact_events is not None:
            self._contact_events.reset()

    # ------------------------------------------------------------------------ properties
    @property
    def config(self) -> SimConfig:
        """The simulator configuration in force."""
        return self.plant.config

    @property
    def started(self) -> bool:
        """Whether :meth:`start` was called."""
        return self._started

    @property
    def finished(self) -> bool:
        """Whether the run is over: ``duration``'s steps taken, or stopped on an event."""
        plant = self.plant
        return plant.stop_reason is not None or plant.step_index >= plant.config.n_steps

    @property
    def stop_reason(self) -> str | None:
        """``"duration"``, the plant's stop reason, or None while the run goes on."""
        if self.plant.stop_reason is not None:
            return self.plant.stop_reason
        return DURATION if self.finished else None

    @property
    def t(self) -> float:
        """Simulation time of the plant's current state, s."""
        return self.plant.observe().t

    def update_config(self, sim_config: SimConfig) -> None:
        """Apply new live parameters (:data:`LIVE_FIELDS`) from the next step on.

        Raises:
            ValueError: A read-only field (initial state, integrator, time step, duration,
                lockstep, publish_clock) differs from the one in force.
        """
        current = self.plant.config
        changed = [
            f.name
            for f in dataclasses.fields(SimConfig)
            if f.name not in LIVE_FIELDS
            and not np.array_equal(getattr(sim_config, f.name), getattr(current, f.name))
        ]
        if changed:
            raise ValueError(
                f'{type(self).__name__}.update_config: {changed} are read-only while the '
                'simulator runs'
            )
        self.plant.config = sim_config

    # ------------------------------------------------------------------------- internals
    def _step_plant(self, effort: np.ndarray) -> StepReport:
        """Step the plant with ``effort`` (m,), N·m; keep it as the applied one if integrated."""
        self.plant.step(effort)
        report = self.plant.last_report
        if report.state is not report.start:  # integrated (a rigid stop is not)
            self._applied_effort = np.array(report.effort)
        return report

    def _contact_event_report(self) -> DiagnosticReport | None:
        """Return a WARN ``hand_sim`` status if the last step lost a contact or the object."""
        if self._contact_events is None:
            return None
        onsets = self._contact_events.update(self.plant.contact_report())
        if not onsets:
            return None
        return contact_event_report(onsets, self.t, self._contact_events.events().to_values())

    def _end_of_run_report(self) -> DiagnosticReport:
        """Return the end-of-run ``hand_sim`` status (once: the run is then reported ended)."""
        self._reported_end = True
        events = None if self._contact_events is None else self._contact_events.events()
        return end_of_run_report(
            self.stop_reason,
            self.t,
            self.plant.step_index,
            None if events is None else events.to_values(),
        )
