"""``SAFETY_FILTER_PARAMETERS``: constraints, barriers, relaxation, QP, input handling."""

from __future__ import annotations

from grasp_safety_filter.control.constraints.friction_cone import (
    FRICTION_CONES,
    INSCRIBED,
    MAX_FRICTION_MARGIN,
)
from grasp_safety_filter.control.qp import QP_METRICS
from grasp_safety_filter.io.parameters import (
    ParameterSpec,
)
from grasp_safety_filter.io.schemas.common import (
    BOOL,
    DOUBLE,
    FINGERTIP_WORKSPACE_A_MARGIN,
    HALF_PI,
    INTEGER,
    MAX_OSQP_ITERATIONS,
    MAX_PYRAMID_FACES,
    STRING,
)
from grasp_safety_filter.io.schemas.nominal import GRASP_CHECK_PARAMETERS

# fmt: off
SAFETY_FILTER_QP_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'no_slip.enabled', BOOL, True,
        'Keep every contact force inside its friction pyramid',
    ),
    ParameterSpec(
        'no_slip.pyramid_faces', INTEGER, 8,
        'Faces l_s of the friction pyramid inscribed in each cone (at most 64: cos(pi/64) = '
        '99.9 % of the cone; more only add QP rows) [-]',
        min_value=3, max_value=MAX_PYRAMID_FACES, read_only=True,
    ),
    ParameterSpec(
        'no_slip.normal_force_margin', DOUBLE, 0.01,
        'Margin eps of the pyramid rows, Lambda(mu) f_c <= -eps [N]',
        min_value=0.0,
    ),
    ParameterSpec(
        'no_slip.friction_margin', DOUBLE, 0.0,
        'Relative friction margin m: the rows use mu (1 - m), a cone inside a plant whose '
        'friction is at least (1 - m) mu [-]',
        min_value=0.0, max_value=MAX_FRICTION_MARGIN,
    ),
    ParameterSpec(
        'no_slip.cone', STRING, INSCRIBED,
        "Friction pyramid: inscribed (l_s faces inside the circular cone, the paper's) or "
        "diamond (|f_x| + |f_y| <= mu f_n, also inside a pyramidal contact model's cone)",
        choices=FRICTION_CONES, read_only=True,
    ),
    ParameterSpec(
        'torque_rate.enabled', BOOL, False,
        'Bound the step of every joint torque per tick, |u_k - u_k-1| <= max_step (not a '
        'safety constraint: relaxed first)',
    ),
    ParameterSpec(
        'torque_rate.max_step', DOUBLE, 0.2,
        'Largest change of a joint torque from one tick to the next [N m]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'torque_rate.max_rate', DOUBLE, 0.0,
        'Largest rate of change of a joint torque, times the time since the last tick; '
        'the tighter of it and max_step applies (0: none, max_step alone) [N m/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'joint_limits.enabled', BOOL, True,
        'Keep every joint inside its URDF limits (relative-degree-2 barrier)',
    ),
    ParameterSpec(
        'joint_limits.margin', DOUBLE, 0.02,
        'Distance the barrier keeps from every joint limit, so that what a control period '
        'overshoots stays inside the limits (0: the limits themselves, as in the paper) [rad]',
        min_value=0.0,
    ),
    ParameterSpec(
        'fingertip_workspace.enabled', BOOL, True,
        'Keep every contact point inside the fingertip workspace (relative-degree-2 barrier)',
    ),
    ParameterSpec(
        'fingertip_workspace.margin', DOUBLE, 0.02,
        'Distance the barrier keeps from every fingertip workspace bound (0: the bounds '
        'themselves, as in the paper) [rad]',
        min_value=0.0,
    ),
    ParameterSpec(
        'object_workspace.enabled', BOOL, True,
        'Keep every contact point on its object surface, a margin inside a box face '
        '(relative-degree-2 barrier; off in the paper)',
    ),
    ParameterSpec(
        'object_workspace.margin', DOUBLE, 0.005,
        'Distance the contact points keep from the edges of their box face, below every '
        'half extent [m]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'object_workspace.sphere_a_half_width', DOUBLE, 1.0,
        "On a sphere object: |a| the contact keeps in its chart, off the chart's poles at "
        '+-pi/2 [rad]',
        min_value=0.0, max_value=HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN, exclusive_min=True,
    ),
    ParameterSpec(
        'object_workspace.sphere_b_half_width', DOUBLE, 1.0,
        "On a sphere object: |b + pi/2| the contact keeps in its chart, off the chart's cut "
        'at b = +-pi [rad]',
        min_value=0.0, max_value=HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN, exclusive_min=True,
    ),
    ParameterSpec(
        'barrier.alpha1.kind', STRING, 'linear',
        "Class-K function alpha1: cubic g h^3 (the paper's) or linear g h",
        choices=('cubic', 'linear'),
    ),
    ParameterSpec(
        'barrier.alpha1.gain', DOUBLE, 20.0,
        'Gain g of alpha1, h in rad [1/(s rad^2) if cubic, 1/s if linear]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'barrier.alpha2.kind', STRING, 'linear',
        "Class-K function alpha2: cubic g B^3 (the paper's) or linear g B",
        choices=('cubic', 'linear'),
    ),
    ParameterSpec(
        'barrier.alpha2.gain', DOUBLE, 20.0,
        'Gain g of alpha2, B in rad/s [s/rad^2 if cubic, 1/s if linear]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.no_slip_weight', DOUBLE, 1.0e6,
        'Penalty on the squared slack of the no-slip rows when the QP is infeasible [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.joint_limits_weight', DOUBLE, 1.0e6,
        'Penalty on the squared slack of the joint-limit rows when infeasible [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.fingertip_workspace_weight', DOUBLE, 1.0e3,
        'Penalty on the squared slack of the fingertip-workspace rows when infeasible [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.object_workspace_weight', DOUBLE, 1.0e3,
        'Penalty on the squared slack of the object-workspace rows when infeasible [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.torque_rate_weight', DOUBLE, 1.0e3,
        'Penalty on the squared slack of the torque-rate rows when infeasible (at most '
        'every safety weight) [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.eps_abs', DOUBLE, 1.0e-4,
        'OSQP absolute tolerance [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.eps_rel', DOUBLE, 1.0e-4,
        'OSQP relative tolerance [-]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.max_iter', INTEGER, 50,
        'OSQP iteration limit per solve (at most 100000, about 0.1 s per tick) [-]',
        min_value=1, max_value=MAX_OSQP_ITERATIONS,
    ),
    ParameterSpec(
        'osqp.polish', BOOL, True,
        'Polish the OSQP solution on the rows it finds active (an unpolished answer rarely passes '
        'the KKT check, and daqp then finishes the tick)',
    ),
    ParameterSpec(
        'qp.solver', STRING, 'daqp',
        'QP backend: daqp (dual active set, exact) or osqp (ADMM, its polished answer '
        'KKT-checked, finished by daqp when the check fails)',
        choices=('osqp', 'daqp'),
    ),
    ParameterSpec(
        'qp.metric', STRING, 'acceleration',
        "Cost of the correction du = u - u_nom: identity ||du||^2 (the paper's), "
        'inverse_inertia du^T W du, W = (tr(M_h)/m) M_h^-1 (the kinetic-energy norm of the '
        'joint acceleration du excites; relaxation slack then in W distance) or '
        'acceleration (that norm of the acceleration du gives the grasped hand and the '
        'object: internal forces are nearly free)',
        choices=QP_METRICS,
    ),
)
# fmt: on
"""The safety filter's own parameters (read by ``SafetyFilterConfig``)."""

# fmt: off
SAFETY_FILTER_INPUT_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'input.max_age', DOUBLE, 0.05,
        'State or nominal command older than this is stale and rejected [s]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'input.hold_timeout', DOUBLE, 0.1,
        'After rejected input, hold the last safe command this long, then fall back [s]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'input.fallback', STRING, 'gravity_compensation',
        'Command after the hold timeout: zero torque or gravity_compensation',
        choices=('zero', 'gravity_compensation'),
    ),
)
# fmt: on
"""How the safety filter node treats stale or invalid input (``InputPolicyConfig``)."""

# fmt: off
SAFETY_FILTER_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'enabled', BOOL, True,
        'Filter on; false passes u_nom through unchanged (still validated), e.g. for the '
        "paper's nominal run",
    ),
    *SAFETY_FILTER_QP_PARAMETERS,
    *SAFETY_FILTER_INPUT_PARAMETERS,
    *GRASP_CHECK_PARAMETERS,
    ParameterSpec(
        'diagnostics.period', DOUBLE, 0.1,
        'Least stamp interval between two /diagnostics statuses of unchanged good ticks '
        '(solved, nominal, off); every other tick is published; 0: every tick [s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'margins.period', DOUBLE, 0.0,
        'Least stamp interval between two /safety_filter/margins messages; 0: every tick [s]',
        min_value=0.0,
    ),
)
# fmt: on
