"""The grasp-markers endpoint: the newest state in, ``/grasp/markers`` out when asked.

Pure Python, shared by the rclpy node (:mod:`~grasp_safety_filter.nodes.grasp_markers_node`)
and tests. It keeps the newest message of each input and parses it when it draws, as the
controllers parse them (joints by name, others ignored), so that a 1 kHz driver costs it a
reference per message:

- ``/hand/joint_states`` and ``/object/odom``: the configuration (both needed);
- ``/hand/contacts`` (the simulator's): the contact forces and the friction used, for the
  force arrows and the cones' colours (without them: no arrows, grey cones);
- ``/diagnostics``: the ``safety_filter`` status's ``active`` rows.

:meth:`GraspMarkersEndpoint.markers` draws that newest state
(:func:`~grasp_safety_filter.view.markers.scene_markers`), stamped as its joint state, in the
palm frame. It runs off the control loop: the node calls it on a timer, and input it cannot
parse is counted and named, never raised.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import (
    contacts_from_msg,
    diagnostics_from_msg,
    joint_state_from_msg,
    MessageError,
    MessageNamespace,
    odometry_from_msg,
)
from grasp_safety_filter.io.messages.markers import MarkerArrayBuilder
from grasp_safety_filter.io.topics import CONTACTS, DIAGNOSTICS, JOINT_STATES, OBJECT_ODOM
from grasp_safety_filter.view.markers import scene_markers
from grasp_safety_filter.view.scene import SceneBuilder


@dataclass(frozen=True)
class MarkerConfig:
    """``markers.*``.

    Attributes:
        rate: Publications per second, at most, Hz.
        force_scale: Force arrows' length per newton, m/N.
    """

    rate: float = 30.0
    force_scale: float = 0.005

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> MarkerConfig:
        """Read ``markers.rate`` and ``markers.force_scale``."""
        return cls(float(params['markers.rate']), float(params['markers.force_scale']))


class GraspMarkersEndpoint:
    """The newest grasp state as markers (module docstring).

    Args:
        model: The ``GraspModel`` (its URDF, joints, contacts, friction, palm frame).
        msgs: Message classes to build.
        config: ``markers.*``.

    Attributes:
        rejected: Inputs that did not parse, by topic.
        last_error: The last of them, as text (None: none).
    """

    def __init__(self, model: Any, msgs: MessageNamespace, config: MarkerConfig) -> None:
        self.model = model
        self.msgs = msgs
        self.config = config
        self.builder = SceneBuilder(model)
        self.messages = MarkerArrayBuilder(msgs, model.palm_frame)
        self.rejected: dict[str, int] = {}
        self.last_error: str | None = None
        names, contacts = model.joint_names, model.contact_names
        palm, body = model.palm_frame, model.object_frame
        self._parsers = {
            JOINT_STATES: lambda msg: joint_state_from_msg(msg, names, JOINT_STATES, others=True),
            OBJECT_ODOM: lambda msg: odometry_from_msg(msg, palm, body, OBJECT_ODOM),
            CONTACTS: lambda msg: contacts_from_msg(msg, contacts, CONTACTS),
        }
        self._received: dict[str, Any] = {}  # the newest message, by topic
        self._parsed: dict[str, Any] = {}  # the newest that parsed
        self._active: tuple[str, ...] = ()
        self._drawn: Any = None  # the last array, while nothing new came

    def on_joint_states(self, msg: Any) -> None:
        """Keep the newest joint state."""
        self._received[JOINT_STATES] = msg

    def on_odom(self, msg: Any) -> None:
        """Keep the newest object pose."""
        self._received[OBJECT_ODOM] = msg

    def on_contacts(self, msg: Any) -> None:
        """Keep the newest contact forces (the simulator's ``/hand/contacts``)."""
        self._received[CONTACTS] = msg

    def _parse(self, topic: str) -> Any:
        """Return the newest message of ``topic`` that parsed (None: none yet)."""
        msg = self._received.pop(topic, None)
        if msg is not None:
            try:
                self._parsed[topic] = self._parsers[topic](msg)
            except MessageError as error:
                self.rejected[topic] = self.rejected.get(topic, 0) + 1
                self.last_error = str(error)
        return self._parsed.get(topic)

    def on_diagnostics(self, msg: Any) -> None:
        """Keep the safety filter's active rows, from its status when it has one."""
        try:
            reports = diagnostics_from_msg(msg, DIAGNOSTICS).reports
        except MessageError as error:
            self.rejected[DIAGNOSTICS] = self.rejected.get(DIAGNOSTICS, 0) + 1
            self.last_error = str(error)
            return
        for report in reports:
            if report.name == FILTER_DIAGNOSTIC and Key.ACTIVE in report.values:
                text = report.values[Key.ACTIVE]
                active = tuple(row for row in text.split(',') if row)
                if active != self._active:
                    self._active, self._drawn = active, None

    def markers(self) -> Any | None:
        """Return the newest state's ``MarkerArray``; None before a joint state and a pose.

        A state the model refuses (a degenerate contact) is not drawn: None, and
        ``last_error`` says why. Nothing new since the last call: that array again (its
        markers are updated in place by the next drawing).
        """
        if self._drawn is not None and not self._received:
            return self._drawn
        joints, pose = self._parse(JOINT_STATES), self._parse(OBJECT_ODOM)
        contacts = self._parse(CONTACTS)
        if joints is None or pose is None:
            return None
        force = beta = None
        if contacts is not None:
            force, beta = contacts.force, contacts.required_friction
        try:
            scene = self.builder.scene(
                joints.t, joints.position, pose.p_object_in_palm, pose.R_object_to_palm, force
            )
        except ValueError as error:
            self.last_error = f'state not drawn: {error}'
            self._drawn = None
            return None
        specs = scene_markers(
            scene,
            self.model.friction_coefficient,
            beta,
            self._active,
            self.config.force_scale,
        )
        self._drawn = self.messages.build(joints.stamp_ns, specs)
        return self._drawn
