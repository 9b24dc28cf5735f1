"""``NOMINAL_CONTROLLER_PARAMETERS`` and the controllers' grasp check."""

from __future__ import annotations

from grasp_safety_filter.io.parameters import (
    ParameterSpec,
)
from grasp_safety_filter.io.schemas.common import DOUBLE, DOUBLE_ARRAY, STRING

#: The start-up check's gap tolerance (``model.grasp_check.GAP_TOLERANCE``), m: the default
#: of both controllers' ``grasp_check.gap_tolerance`` (test_grasp_check compares them).
GRASP_CHECK_GAP_TOLERANCE = 1e-3

# fmt: off
GRASP_CHECK_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'grasp_check.gap_tolerance', DOUBLE, GRASP_CHECK_GAP_TOLERANCE,
        'Largest gap or penetration between a fingertip and the object per contact; a state '
        'beyond it is no grasp (start-up and run-time check) [m]',
        min_value=0.0, exclusive_min=True,
    ),
)
# fmt: on
"""The grasp check of the received states (``nodes.grasp_watch.GraspCheckConfig``)."""

# fmt: off
NOMINAL_CONTROLLER_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'gains.kp', DOUBLE, 1.0,
        'Pose-error gain K_p = kp I_6 of the computed-torque law [1/s^2]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'gains.kd', DOUBLE, 2.5,
        'Velocity-error gain K_d = kd I_6 of the computed-torque law [1/s]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'gains.kf', DOUBLE, 10.0,
        'Internal squeeze gain k_f in u_f,i = k_f (p_bar_c - p_c,i) [N/m]',
        min_value=0.0,
    ),
    ParameterSpec(
        'null_space.kp', DOUBLE, 25.0,
        'Posture gain per unit joint inertia on the internal finger motion (null(J_h), '
        'hands with m > 3n joints), tau_null = N^T M_h (-kp (q - q_posture) - kd dq), '
        'q_posture the first joint positions seen [1/s^2]',
        min_value=0.0,
    ),
    ParameterSpec(
        'null_space.kd', DOUBLE, 10.0,
        'Damping gain per unit joint inertia on the internal finger motion (null(J_h)) [1/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'reference.source', STRING, 'paper',
        'Object pose reference: paper (built-in r(t)) or topic (/object/reference)',
        choices=('paper', 'topic'), read_only=True,
    ),
    ParameterSpec(
        'reference.amplitude', DOUBLE_ARRAY, [0.0, 0.0, 0.25, 0.0, 0.0, 2.0],
        'Amplitude A of the built-in r(t) = r0 + A (cos(w t) - 1), r0 the initial pose: '
        'x y z [m], roll pitch yaw (ZYX Euler) [rad]',
        length=6,
    ),
    ParameterSpec(
        'reference.frequency', DOUBLE, 1.0,
        'Angular frequency w of the built-in reference (0: hold the initial pose) [rad/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'reference.timeout', DOUBLE, 0.5,
        'A topic reference older than this is stale [s]',
        min_value=0.0, exclusive_min=True,
    ),
)
# fmt: on
"""The nominal controller's gains and reference (read by ``NominalConfig``); its node also
declares :data:`GRASP_CHECK_PARAMETERS`."""
