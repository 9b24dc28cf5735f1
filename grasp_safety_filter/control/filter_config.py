"""The safety filter's configuration: constraints, barriers, relaxation weights, QP solver."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.io.parameters import flatten_parameters, ParameterError
from grasp_safety_filter.io.schemas import SAFETY_FILTER_QP_PARAMETERS

#: Config field of each parameter.
_FIELDS: dict[str, str] = {
    'no_slip.enabled': 'no_slip_enabled',
    'no_slip.pyramid_faces': 'pyramid_faces',
    'no_slip.normal_force_margin': 'normal_force_margin',
    'no_slip.friction_margin': 'friction_margin',
    'no_slip.cone': 'cone',
    'torque_rate.enabled': 'torque_rate_enabled',
    'torque_rate.max_step': 'torque_rate_max_step',
    'torque_rate.max_rate': 'torque_rate_max_rate',
    'joint_limits.enabled': 'joint_limits_enabled',
    'joint_limits.margin': 'joint_limits_margin',
    'fingertip_workspace.enabled': 'fingertip_workspace_enabled',
    'fingertip_workspace.margin': 'fingertip_workspace_margin',
    'object_workspace.enabled': 'object_workspace_enabled',
    'object_workspace.margin': 'object_workspace_margin',
    'object_workspace.sphere_a_half_width': 'object_workspace_sphere_a_half_width',
    'object_workspace.sphere_b_half_width': 'object_workspace_sphere_b_half_width',
    'barrier.alpha1.kind': 'alpha1_kind',
    'barrier.alpha1.gain': 'alpha1_gain',
    'barrier.alpha2.kind': 'alpha2_kind',
    'barrier.alpha2.gain': 'alpha2_gain',
    'relaxation.no_slip_weight': 'no_slip_weight',
    'relaxation.joint_limits_weight': 'joint_limits_weight',
    'relaxation.fingertip_workspace_weight': 'fingertip_workspace_weight',
    'relaxation.object_workspace_weight': 'object_workspace_weight',
    'relaxation.torque_rate_weight': 'torque_rate_weight',
    'osqp.eps_abs': 'eps_abs',
    'osqp.eps_rel': 'eps_rel',
    'osqp.max_iter': 'max_iter',
    'osqp.polish': 'polish',
    'qp.solver': 'solver',
    'qp.metric': 'metric',
}


@dataclass(frozen=True)
class SafetyFilterConfig:
    """Which constraints, how they decay, how they relax, which QP solver (see the parameters).

    Attributes:
        no_slip_enabled: Enforce the friction pyramids.
        pyramid_faces: Pyramid faces l_s (>= 3).
        normal_force_margin: Pyramid margin eps, N (>= 0).
        friction_margin: Relative friction margin m in [0, 0.9]: the rows use mu (1 - m).
        cone: ``"inscribed"`` (l_s faces) or ``"diamond"`` (|f_x| + |f_y| <= mu f_n).
        torque_rate_enabled: Bound the torque step per tick.
        torque_rate_max_step: That bound, N·m per tick (> 0).
        torque_rate_max_rate: The bound per second, N·m/s (>= 0; 0: none): per tick the
            tighter of ``max_step`` and ``max_rate`` times the time since the last tick.
        joint_limits_enabled: Enforce the joint-limit barriers.
        joint_limits_margin: Distance the barriers keep from the joint limits, rad (>= 0).
        fingertip_workspace_enabled: Enforce the fingertip-workspace barriers.
        fingertip_workspace_margin: Distance they keep from the workspace bounds, rad.
        object_workspace_enabled: Enforce the object-workspace barriers.
        object_workspace_margin: Distance kept from a box face's edges, m (> 0).
        object_workspace_sphere_a_half_width, object_workspace_sphere_b_half_width: The box
            ``|a| <= w_a, |b + pi/2| <= w_b`` of a contact's sphere chart, rad.
        alpha1_kind, alpha1_gain: alpha_1 (``"cubic"`` or ``"linear"``, gain > 0).
        alpha2_kind, alpha2_gain: alpha_2 (same choices).
        no_slip_weight, joint_limits_weight, fingertip_workspace_weight,
            object_workspace_weight, torque_rate_weight: Slack weights of the relaxed QP
            (> 0), per (N·m)² of torque-space violation (of W-distance violation with the
            inverse-inertia metric).
            The torque-rate weight is at most every safety weight.
        eps_abs, eps_rel: OSQP tolerances (> 0).
        max_iter: OSQP iteration limit (>= 1).
        polish: OSQP solution polishing.
        solver: The QP backend (a key of
            :data:`~grasp_safety_filter.control.qp_solvers.BACKENDS`).
        metric: The QP cost's metric (:data:`~grasp_safety_filter.control.qp.QP_METRICS`):
            ``"identity"`` (the paper's), ``"inverse_inertia"`` or ``"acceleration"``.
    """

    no_slip_enabled: bool = True
    pyramid_faces: int = 8
    normal_force_margin: float = 0.01
    friction_margin: float = 0.0
    cone: str = 'inscribed'
    torque_rate_enabled: bool = False
    torque_rate_max_step: float = 0.2
    torque_rate_max_rate: float = 0.0
    joint_limits_enabled: bool = True
    joint_limits_margin: float = 0.02
    fingertip_workspace_enabled: bool = True
    fingertip_workspace_margin: float = 0.02
    object_workspace_enabled: bool = True
    object_workspace_margin: float = 0.005
    object_workspace_sphere_a_half_width: float = 1.0
    object_workspace_sphere_b_half_width: float = 1.0
    alpha1_kind: str = 'linear'
    alpha1_gain: float = 20.0
    alpha2_kind: str = 'linear'
    alpha2_gain: float = 20.0
    no_slip_weight: float = 1e6
    joint_limits_weight: float = 1e6
    fingertip_workspace_weight: float = 1e3
    object_workspace_weight: float = 1e3
    torque_rate_weight: float = 1e3
    eps_abs: float = 1e-4
    eps_rel: float = 1e-4
    max_iter: int = 50
    polish: bool = True
    solver: str = 'daqp'
    metric: str = 'acceleration'

    def __post_init__(self) -> None:
        for spec in SAFETY_FILTER_QP_PARAMETERS:
            name = _FIELDS[spec.name]
            object.__setattr__(self, name, spec.validate(getattr(self, name)))
        safety = {
            'relaxation.no_slip_weight': self.no_slip_weight,
            'relaxation.joint_limits_weight': self.joint_limits_weight,
            'relaxation.fingertip_workspace_weight': self.fingertip_workspace_weight,
            'relaxation.object_workspace_weight': self.object_workspace_weight,
        }
        for name, weight in safety.items():
            if self.torque_rate_enabled and self.torque_rate_weight > weight:
                raise ParameterError(
                    f"'relaxation.torque_rate_weight': expected at most every safety weight "
                    '(a safety row is never given up for the rate), got '
                    f'{self.torque_rate_weight!r} > '
                    f"'{name}' = {weight!r}"
                )

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> SafetyFilterConfig:
        """Read the filter's parameters; missing ones take their defaults.

        Args:
            params: Values by dotted name (``{"no_slip.pyramid_faces": 8, ...}``) or as
                nested mappings (``{"no_slip": {"pyramid_faces": 8}}``); other names are
                ignored.

        Raises:
            ParameterError: A value has the wrong type or is out of range; the message names
                the parameter, what was expected and what was received.
        """
        flat = flatten_parameters(params)
        # Validated (and converted) by __post_init__, in the same order.
        return cls(
            **{
                _FIELDS[spec.name]: flat[spec.name]
                for spec in SAFETY_FILTER_QP_PARAMETERS
                if spec.name in flat
            }
        )

    def to_parameters(self) -> dict[str, Any]:
        """Return the configuration as ``{dotted parameter name: value}``."""
        return {
            spec.name: getattr(self, _FIELDS[spec.name]) for spec in SAFETY_FILTER_QP_PARAMETERS
        }

    @property
    def alpha1(self) -> ClassKFunction:
        """alpha_1 as a function."""
        return ClassKFunction(self.alpha1_kind, self.alpha1_gain)

    @property
    def alpha2(self) -> ClassKFunction:
        """alpha_2 as a function."""
        return ClassKFunction(self.alpha2_kind, self.alpha2_gain)

    def osqp_settings(self) -> dict[str, Any]:
        """Return the ``osqp.*`` parameters as ``osqp.OSQP.setup`` settings (backend adds more)."""
        return {
            'eps_abs': self.eps_abs,
            'eps_rel': self.eps_rel,
            'max_iter': self.max_iter,
            'polishing': self.polish,
            # Check convergence every 5 iterations instead of OSQP's 25: the warm-started
            # problems converge in a few, and daqp finishes those that do not.
            'check_termination': 5,
        }

    def solver_settings(self) -> dict[str, Any]:
        """Return the chosen backend's settings (OSQP's; none for daqp, which has its own)."""
        return self.osqp_settings() if self.solver == 'osqp' else {}


#: The paper's filter: its cubic class-K functions of gain 1, the bounds themselves (no
#: margins), no object-workspace barriers, the identity metric. The defaults differ on those,
#: as measured on 500 hands not designed with the filter (docs/any_hand.md):
#: - linear functions use any margin, in any unit, in 1/k1 + 1/k2 = 0.1 s, where h^3 freezes
#:   a joint 0.1 rad from its limit;
#: - they let coordinates reach their bounds, and a 1 ms hold misses a row's acceleration by
#:   a few rad/s^2 on light fingers: the barrier settles delta / (k1 k2) past its margin,
#:   9e-3 rad at 3.5 rad/s^2 with gains 20, inside the 0.02 rad margins;
#: - contacts kept on their object faces (off in the paper);
#: - the acceleration metric corrects a squeeze by internal forces, not by throwing the
#:   object and shaking the fingers at up to 7 rad/s.
PAPER_CONFIG = SafetyFilterConfig(
    joint_limits_margin=0.0,
    fingertip_workspace_margin=0.0,
    object_workspace_enabled=False,
    alpha1_kind='cubic',
    alpha1_gain=1.0,
    alpha2_kind='cubic',
    alpha2_gain=1.0,
    metric='identity',
)
