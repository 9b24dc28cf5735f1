"""The nominal controller's configuration: its gains and its reference, validated.

:class:`NominalConfig` holds the gains of the law in :mod:`grasp_safety_filter.control.nominal`
and the choice of object reference, checked against the ``nominal_controller_node``
parameter schema, and builds that reference source.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.control.reference import (
    PAPER_AMPLITUDE,
    PAPER_FREQUENCY,
    PaperReference,
    Pose,
    ReferenceSource,
    TopicReference,
)
from grasp_safety_filter.io.parameters import flatten_parameters, ParameterError
from grasp_safety_filter.io.schemas import NOMINAL_CONTROLLER_PARAMETERS


@dataclass(frozen=True)
class NominalConfig:
    """Gains and reference choice of the nominal controller (paper values by default).

    Attributes:
        kp: Proportional gain, K_p = kp I, 1/s².
        kd: Derivative gain, K_d = kd I, 1/s.
        kf: Squeeze gain k_f, N/m.
        null_space_kp: Posture gain k_null,p of the null(J_h) motion, per unit inertia, 1/s².
        null_space_kd: Damping gain k_null,d of the null(J_h) motion, per unit inertia, 1/s.
        reference_source: ``"paper"`` or ``"topic"``.
        amplitude: Paper reference amplitude, shape (6,), m and rad.
        frequency: Paper reference angular frequency, rad/s.
        timeout: Topic reference timeout, s.

    """

    kp: float = 1.0
    kd: float = 2.5
    kf: float = 10.0
    null_space_kp: float = 25.0
    null_space_kd: float = 10.0
    reference_source: str = 'paper'
    amplitude: tuple[float, ...] = PAPER_AMPLITUDE
    frequency: float = PAPER_FREQUENCY
    timeout: float = 0.5

    def __post_init__(self) -> None:
        values = {
            'gains.kp': self.kp,
            'gains.kd': self.kd,
            'gains.kf': self.kf,
            'null_space.kp': self.null_space_kp,
            'null_space.kd': self.null_space_kd,
            'reference.source': self.reference_source,
            'reference.amplitude': list(self.amplitude),
            'reference.frequency': self.frequency,
            'reference.timeout': self.timeout,
        }
        for spec in NOMINAL_CONTROLLER_PARAMETERS:
            spec.validate(values[spec.name])
        object.__setattr__(self, 'amplitude', tuple(float(a) for a in self.amplitude))

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> NominalConfig:
        """Read the controller's parameters; missing ones take their defaults.

        Args:
            params: Parameter values by dotted name (``{"gains.kp": 1.0, ...}``) or as
                nested mappings (``{"gains": {"kp": 1.0}}``); other names are ignored.

        Raises:
            ParameterError: A value has the wrong type or is out of range; the message names
                the parameter, what was expected and what was received.

        """
        flat = flatten_parameters(params)
        values = {
            spec.name: spec.validate(flat[spec.name]) if spec.name in flat else spec.default
            for spec in NOMINAL_CONTROLLER_PARAMETERS
        }
        return cls(
            kp=float(values['gains.kp']),
            kd=float(values['gains.kd']),
            kf=float(values['gains.kf']),
            null_space_kp=float(values['null_space.kp']),
            null_space_kd=float(values['null_space.kd']),
            reference_source=values['reference.source'],
            amplitude=tuple(values['reference.amplitude']),
            frequency=float(values['reference.frequency']),
            timeout=float(values['reference.timeout']),
        )

    def make_reference(self, initial_pose: Pose, t0: float = 0.0) -> ReferenceSource:
        """Build the configured reference source, starting at the initial object pose at t0."""
        if self.reference_source == 'paper':
            return PaperReference(initial_pose, self.amplitude, self.frequency, t0)
        if self.reference_source == 'topic':
            return TopicReference(initial_pose, self.timeout)
        raise ParameterError(
            f"parameter 'reference.source': expected 'paper' or 'topic', got "
            f'{self.reference_source!r}'
        )
