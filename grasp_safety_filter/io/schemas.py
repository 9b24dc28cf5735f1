"""The parameters of the three nodes, as data.

Sections:

- ``MODEL_PARAMETERS``: the hand, the object and their contacts. Shared by all three nodes
  and placed under ``/**`` in the parameter files, so that the simulator and the controllers
  cannot disagree about the plant.
- ``HAND_SIM_PARAMETERS``, ``NOMINAL_CONTROLLER_PARAMETERS``, ``SAFETY_FILTER_PARAMETERS``:
  each node's own.

``NODE_SCHEMAS[node]`` is the model section followed by the node's own. Defaults are the
paper's Section IV scenario (``config/paper_scenario.yaml`` spells each one out, with the
reason for every value the paper does not give). Checks that need only parameter values
(e.g. ``a_min < a_max``) live here; checks against the URDF and the object geometry belong
to the model.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
import math
from pathlib import Path
from typing import Any

from grasp_safety_filter.control.constraints.friction_cone import (
    FRICTION_CONES,
    INSCRIBED,
    MAX_FRICTION_MARGIN,
)
from grasp_safety_filter.control.qp_metric import QP_METRICS
from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    misspelt_node_sections,
    NodeSchema,
    parameters_for_node,
    ParameterSpec,
    ParameterType,
    raise_parameter_errors,
    resolve_relative_paths,
    validate_parameters,
)
from grasp_safety_filter.io.plant_schema import PLANT_PARAMETERS

BOOL = ParameterType.BOOL
INTEGER = ParameterType.INTEGER
DOUBLE = ParameterType.DOUBLE
STRING = ParameterType.STRING
DOUBLE_ARRAY = ParameterType.DOUBLE_ARRAY
STRING_ARRAY = ParameterType.STRING_ARRAY

HALF_PI = math.pi / 2

#: Object faces a fingertip can touch, in the object frame O (outward normal).
CUBE_FACES = ('+x', '-x', '+y', '-y', '+z', '-z')

#: The paper's hand (config/hand.urdf): three fingers of three revolute joints.
PAPER_JOINT_NAMES = [f'finger{finger}_joint{joint}' for finger in (1, 2, 3) for joint in (1, 2, 3)]

#: Joint angles of the paper's initial static grasp, per finger (joint1, joint2, joint3) [rad].
PAPER_FINGER_JOINT_POSITIONS = [3 * math.pi / 4, 0.0, HALF_PI]

#: The fingertip coordinate a is kept this far from +-pi/2, where the sphere's metric
#: M_cf = diag(R, R cos a) is singular [rad].
FINGERTIP_WORKSPACE_A_MARGIN = 0.15

#: Most faces of a friction pyramid: a pyramid of l_s faces adds l_s QP rows per contact
#: (memory and time grow with them; 100000 faces asked for 1.3 TiB), and 64 faces already
#: cover cos(pi/64) = 99.9 % of the cone.
MAX_PYRAMID_FACES = 64

#: Most OSQP iterations per solve: at about 1 us each, a tick stays below ~0.1 s.
MAX_OSQP_ITERATIONS = 100_000

#: ``expected_outcome`` of the paper's scenario: Shaw-Cortez et al. (CDC 2018), Section IV.
PAPER_OUTCOME = 'paper'
#: ``expected_outcome`` of a scenario without a published outcome (only the generic verdict).
NO_OUTCOME = 'none'
#: Admissible ``expected_outcome`` values.
EXPECTED_OUTCOMES = (NO_OUTCOME, PAPER_OUTCOME)

#: Contact-face entry asking for the box face nearest to the fingertip at the first state.
NEAREST_FACE = 'nearest'

#: The model parameters that describe the hand and the object: a scenario must give them (the
#: schema's defaults, the paper's hand's, only fix their ROS types and are never used).
#: ``model.object.size`` (cube, sphere) or ``model.object.edge_lengths`` (box) depends on
#: ``model.object.shape`` (:func:`required_model_parameters`).
REQUIRED_MODEL_PARAMETERS = (
    'model.urdf_file',
    'model.joint_names',
    'model.fingertip_frames',
    'model.contact_names',
    'model.object.shape',
    'model.object.mass',
    'model.friction_coefficient',
    'model.fingertip_workspace.a_min',
    'model.fingertip_workspace.a_max',
    'model.fingertip_workspace.b_min',
    'model.fingertip_workspace.b_max',
)


def required_model_parameters(given: Mapping[str, Any]) -> tuple[str, ...]:
    """:data:`REQUIRED_MODEL_PARAMETERS` and the object's dimensions for its given shape."""
    shape = given.get('model.object.shape')
    if shape == 'box':
        return (*REQUIRED_MODEL_PARAMETERS, 'model.object.edge_lengths')
    if shape in ('cube', 'sphere'):
        return (*REQUIRED_MODEL_PARAMETERS, 'model.object.size')
    return REQUIRED_MODEL_PARAMETERS


def _required(description: str) -> str:
    """Mark ``description`` required, before its ``[unit]`` if it ends with one."""
    text, bracket, unit = description.rpartition(' [')
    if bracket and description.endswith(']'):
        return f'{text}; required (the default is never used) [{unit}'
    return description + '; required (the default is never used)'


MODEL_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'model.urdf_file',
        STRING,
        'hand.urdf',
        _required(
            "Hand URDF; a relative path resolves against the parameter file's directory"
        ),
        read_only=True,
        is_path=True,
    ),
    ParameterSpec(
        'model.joint_names',
        STRING_ARRAY,
        PAPER_JOINT_NAMES,
        _required(
            'Actuated URDF joints, in the order of every joint vector and torque command'
        ),
        read_only=True,
    ),
    ParameterSpec(
        'model.fingertip_frames',
        STRING_ARRAY,
        ['finger1_tip', 'finger2_tip', 'finger3_tip'],
        _required(
            'URDF frames of the fingertips, one per contact (z out of the tip); each fingertip is '
            "the <collision><sphere> on its frame's link (or a link fixed to it): radius R_i, and "
            "its centre the fingertip frame's origin"
        ),
        read_only=True,
    ),
    ParameterSpec(
        'model.contact_names',
        STRING_ARRAY,
        ['finger1', 'finger2', 'finger3'],
        _required(
            'Contact labels, one per fingertip frame (topics, diagnostics, figures)'
        ),
        read_only=True,
    ),
    ParameterSpec(
        'model.fingertip_radius',
        DOUBLE,
        0.0,
        'Deprecated check: 0 (default): each R_i from its collision sphere; > 0: every '
        'fingertip collision sphere must have this radius [m]',
        min_value=0.0,
        read_only=True,
    ),
    ParameterSpec(
        'model.object.shape',
        STRING,
        'cube',
        _required(
            'Shape of the grasped object (a box of three edge lengths, a cube, a sphere)'
        ),
        choices=('cube', 'box', 'sphere'),
        read_only=True,
    ),
    ParameterSpec(
        'model.object.mass',
        DOUBLE,
        0.11,
        _required(
            'Mass of the object [kg]'
        ),
        min_value=0.0,
        exclusive_min=True,
        read_only=True,
    ),
    ParameterSpec(
        'model.object.size',
        DOUBLE,
        0.2604,
        'Cube edge length or sphere diameter; required for a cube or a sphere [m]',
        min_value=0.0,
        exclusive_min=True,
        read_only=True,
    ),
    ParameterSpec(
        'model.object.edge_lengths',
        DOUBLE_ARRAY,
        [0.2604, 0.2604, 0.2604],
        'Box edge lengths along the object frame O (x, y, z); required for a box [m]',
        min_value=0.0,
        exclusive_min=True,
        length=3,
        read_only=True,
    ),
    ParameterSpec(
        'model.contact_faces',
        STRING_ARRAY,
        [NEAREST_FACE],
        "Box face (outward normal in the object frame O) of each contact, or 'nearest': the "
        'face nearest the fingertip at the first state; a declared face must be that one; one '
        'entry applies to every contact; ignored for a sphere',
        choices=(*CUBE_FACES, NEAREST_FACE),
        read_only=True,
    ),
    ParameterSpec(
        'model.friction_coefficient',
        DOUBLE,
        0.9,
        _required(
            'Coulomb friction coefficient mu between fingertips and object: one for every '
            'contact or a list of one per contact, in model.contact_names order [-]'
        ),
        min_value=0.0,
        exclusive_min=True,
        read_only=True,
        per_contact=True,
    ),
    ParameterSpec(
        'model.gravity',
        DOUBLE_ARRAY,
        [0.0, 0.0, -9.81],
        'Gravitational acceleration in the palm frame P (x, y, z) [m/s^2]',
        length=3,
        read_only=True,
    ),
    ParameterSpec(
        'model.palm_frame',
        STRING,
        '',
        "Palm frame P: the URDF's root link when empty; the frame_id of /object/odom and "
        '/object/reference (checked on receipt)',
        read_only=True,
    ),
    ParameterSpec(
        'model.object_frame',
        STRING,
        'object',
        'Object frame O: the child_frame_id of /object/odom (checked on receipt)',
        read_only=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.a_min',
        DOUBLE,
        -HALF_PI + FINGERTIP_WORKSPACE_A_MARGIN,
        _required(
            'Lower bound of the fingertip contact coordinate a: one for every contact or a '
            'list of one per contact [rad]'
        ),
        min_value=-HALF_PI,
        max_value=HALF_PI,
        read_only=True,
        per_contact=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.a_max',
        DOUBLE,
        HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN,
        _required(
            'Upper bound of the fingertip contact coordinate a: one for every contact or a '
            'list of one per contact [rad]'
        ),
        min_value=-HALF_PI,
        max_value=HALF_PI,
        read_only=True,
        per_contact=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.b_min',
        DOUBLE,
        -math.pi,
        _required(
            'Lower bound of the fingertip contact coordinate b: one for every contact or a '
            'list of one per contact [rad]'
        ),
        min_value=-math.pi,
        max_value=0.0,
        read_only=True,
        per_contact=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.b_max',
        DOUBLE,
        0.0,
        _required(
            'Upper bound of the fingertip contact coordinate b: one for every contact or a '
            'list of one per contact [rad]'
        ),
        min_value=-math.pi,
        max_value=0.0,
        read_only=True,
        per_contact=True,
    ),
)

HAND_SIM_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'initial.joint_positions',
        DOUBLE_ARRAY,
        PAPER_FINGER_JOINT_POSITIONS * 3,
        'Joint angles q(0) of the initial static grasp, in model.joint_names order; required '
        '(the default is never used) [rad]',
        read_only=True,
    ),
    ParameterSpec(
        'initial.object_position',
        DOUBLE_ARRAY,
        [0.0, 0.0, 0.3],
        'Object centre p_o(0) in the palm frame P (x, y, z); required (the default is never '
        'used) [m]',
        length=3,
        read_only=True,
    ),
    ParameterSpec(
        'initial.object_orientation',
        DOUBLE_ARRAY,
        [0.0, 0.0, 0.0, 1.0],
        'Object orientation R_po(0) as a unit quaternion (x, y, z, w) [-]',
        length=4,
        min_value=-1.0,
        max_value=1.0,
        read_only=True,
    ),
    ParameterSpec(
        'integrator',
        STRING,
        'ode3',
        "Fixed-step integrator: ode3 (Bogacki-Shampine, the paper's) or rk4",
        choices=('ode3', 'rk4'),
        read_only=True,
    ),
    ParameterSpec(
        'time_step',
        DOUBLE,
        0.001,
        'Integration and control period (stamps are whole nanoseconds) [s]',
        min_value=1e-9,
        read_only=True,
    ),
    ParameterSpec(
        'duration',
        DOUBLE,
        15.0,
        'Simulated time after which the run ends [s]',
        min_value=0.0,
        exclusive_min=True,
        read_only=True,
    ),
    ParameterSpec(
        'stop_on_slip',
        BOOL,
        False,
        "End the run when a contact's required friction beta exceeds mu",
    ),
    ParameterSpec(
        'stop_on_workspace_exit',
        BOOL,
        True,
        'End the run when a contact point leaves the fingertip workspace',
    ),
    ParameterSpec(
        'expected_outcome',
        STRING,
        NO_OUTCOME,
        'Published outcome the scenario must reproduce, checked by grasp-demo and grasp-analyze '
        '(exit code 1 if not): "paper" (Shaw-Cortez et al. 2018, Sec. IV: the nominal run '
        'slips, passes a joint limit, then stops on leaving the fingertip workspace; the '
        'filtered run holds to the end, nothing violated) or "none"; unused by the simulator',
        choices=EXPECTED_OUTCOMES,
        read_only=True,
    ),
    ParameterSpec(
        'stabilization.position_gain',
        DOUBLE,
        2500.0,
        'Baumgarte gain on the contact-constraint position drift [1/s^2]',
        min_value=0.0,
    ),
    ParameterSpec(
        'stabilization.velocity_gain',
        DOUBLE,
        100.0,
        'Baumgarte gain on the contact-constraint velocity drift [1/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'lockstep',
        BOOL,
        True,
        'Integrate to t_k+1 only after the command stamped t_k arrives',
        read_only=True,
    ),
    ParameterSpec(
        'command_timeout',
        DOUBLE,
        1.0,
        'Lockstep: wall-clock wait for the command stamped t_k before a diagnostic [s]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'publish_clock',
        BOOL,
        True,
        'Publish the simulation time on /clock (for nodes with use_sim_time)',
        read_only=True,
    ),
    ParameterSpec(
        'start.wait_for_recorder',
        STRING,
        '',
        'Start only once this node (e.g. rosbag2_recorder) subscribes to every published '
        'topic of the topic table; empty: do not wait',
        read_only=True,
    ),
    *PLANT_PARAMETERS,
)

#: The start-up check's gap tolerance (``model.grasp_check.GAP_TOLERANCE``), m: the default
#: of both controllers' ``grasp_check.gap_tolerance`` (test_grasp_check compares them).
GRASP_CHECK_GAP_TOLERANCE = 1e-3

GRASP_CHECK_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'grasp_check.gap_tolerance',
        DOUBLE,
        GRASP_CHECK_GAP_TOLERANCE,
        'Largest gap or penetration between a fingertip and the object per contact; a state '
        'beyond it is no grasp (start-up and run-time check) [m]',
        min_value=0.0,
        exclusive_min=True,
    ),
)
"""The grasp check of the received states (``nodes.grasp_watch.GraspCheckConfig``)."""

NOMINAL_CONTROLLER_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'gains.kp',
        DOUBLE,
        1.0,
        'Pose-error gain K_p = kp I_6 of the computed-torque law [1/s^2]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'gains.kd',
        DOUBLE,
        2.5,
        'Velocity-error gain K_d = kd I_6 of the computed-torque law [1/s]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'gains.kf',
        DOUBLE,
        10.0,
        'Internal squeeze gain k_f in u_f,i = k_f (p_bar_c - p_c,i) [N/m]',
        min_value=0.0,
    ),
    ParameterSpec(
        'null_space.kp',
        DOUBLE,
        25.0,
        'Posture gain per unit joint inertia on the internal finger motion (null(J_h), '
        'hands with m > 3n joints), tau_null = N^T M_h (-kp (q - q_posture) - kd dq), '
        'q_posture the first joint positions seen [1/s^2]',
        min_value=0.0,
    ),
    ParameterSpec(
        'null_space.kd',
        DOUBLE,
        10.0,
        'Damping gain per unit joint inertia on the internal finger motion (null(J_h)) [1/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'reference.source',
        STRING,
        'paper',
        'Object pose reference: paper (built-in r(t)) or topic (/object/reference)',
        choices=('paper', 'topic'),
        read_only=True,
    ),
    ParameterSpec(
        'reference.amplitude',
        DOUBLE_ARRAY,
        [0.0, 0.0, 0.25, 0.0, 0.0, 2.0],
        'Amplitude A of the built-in r(t) = r0 + A (cos(w t) - 1), r0 the initial pose: '
        'x y z [m], roll pitch yaw (ZYX Euler) [rad]',
        length=6,
    ),
    ParameterSpec(
        'reference.frequency',
        DOUBLE,
        1.0,
        'Angular frequency w of the built-in reference (0: hold the initial pose) [rad/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'reference.timeout',
        DOUBLE,
        0.5,
        'A topic reference older than this is stale [s]',
        min_value=0.0,
        exclusive_min=True,
    ),
)
"""The nominal controller's gains and reference (read by ``NominalConfig``); its node also
declares :data:`GRASP_CHECK_PARAMETERS`."""

SAFETY_FILTER_QP_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'no_slip.enabled',
        BOOL,
        True,
        'Keep every contact force inside its friction pyramid',
    ),
    ParameterSpec(
        'no_slip.pyramid_faces',
        INTEGER,
        8,
        'Faces l_s of the friction pyramid inscribed in each cone (at most 64: cos(pi/64) = '
        '99.9 % of the cone; more only add QP rows) [-]',
        min_value=3,
        max_value=MAX_PYRAMID_FACES,
        read_only=True,
    ),
    ParameterSpec(
        'no_slip.normal_force_margin',
        DOUBLE,
        0.01,
        'Margin eps of the pyramid rows, Lambda(mu) f_c <= -eps [N]',
        min_value=0.0,
    ),
    ParameterSpec(
        'no_slip.friction_margin',
        DOUBLE,
        0.0,
        'Relative friction margin m: the rows use mu (1 - m), a cone inside a plant whose '
        'friction is at least (1 - m) mu [-]',
        min_value=0.0,
        max_value=MAX_FRICTION_MARGIN,
    ),
    ParameterSpec(
        'no_slip.cone',
        STRING,
        INSCRIBED,
        "Friction pyramid: inscribed (l_s faces inside the circular cone, the paper's) or "
        "diamond (|f_x| + |f_y| <= mu f_n, also inside a pyramidal contact model's cone)",
        choices=FRICTION_CONES,
        read_only=True,
    ),
    ParameterSpec(
        'torque_rate.enabled',
        BOOL,
        False,
        'Bound the step of every joint torque per tick, |u_k - u_k-1| <= max_step (not a '
        'safety constraint: relaxed first)',
    ),
    ParameterSpec(
        'torque_rate.max_step',
        DOUBLE,
        0.2,
        'Largest change of a joint torque from one tick to the next [N m]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'joint_limits.enabled',
        BOOL,
        True,
        'Keep every joint inside its URDF limits (relative-degree-2 barrier)',
    ),
    ParameterSpec(
        'fingertip_workspace.enabled',
        BOOL,
        True,
        'Keep every contact point inside the fingertip workspace (relative-degree-2 barrier)',
    ),
    ParameterSpec(
        'object_workspace.enabled',
        BOOL,
        False,
        'Keep every contact point on its object surface, a margin inside a box face '
        '(relative-degree-2 barrier; off in the paper)',
    ),
    ParameterSpec(
        'object_workspace.margin',
        DOUBLE,
        0.005,
        'Distance the contact points keep from the edges of their box face, below every '
        'half extent [m]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'object_workspace.sphere_a_half_width',
        DOUBLE,
        1.0,
        "On a sphere object: |a| the contact keeps in its chart, off the chart's poles at "
        '+-pi/2 [rad]',
        min_value=0.0,
        max_value=HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN,
        exclusive_min=True,
    ),
    ParameterSpec(
        'object_workspace.sphere_b_half_width',
        DOUBLE,
        1.0,
        "On a sphere object: |b + pi/2| the contact keeps in its chart, off the chart's cut "
        'at b = +-pi [rad]',
        min_value=0.0,
        max_value=HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN,
        exclusive_min=True,
    ),
    ParameterSpec(
        'barrier.alpha1.kind',
        STRING,
        'cubic',
        "Class-K function alpha1: cubic g h^3 (the paper's) or linear g h",
        choices=('cubic', 'linear'),
    ),
    ParameterSpec(
        'barrier.alpha1.gain',
        DOUBLE,
        1.0,
        'Gain g of alpha1, h in rad [1/(s rad^2) if cubic, 1/s if linear]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'barrier.alpha2.kind',
        STRING,
        'cubic',
        "Class-K function alpha2: cubic g B^3 (the paper's) or linear g B",
        choices=('cubic', 'linear'),
    ),
    ParameterSpec(
        'barrier.alpha2.gain',
        DOUBLE,
        1.0,
        'Gain g of alpha2, B in rad/s [s/rad^2 if cubic, 1/s if linear]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.no_slip_weight',
        DOUBLE,
        1.0e6,
        'Penalty on the squared slack of the no-slip rows when the QP is infeasible [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.joint_limits_weight',
        DOUBLE,
        1.0e6,
        'Penalty on the squared slack of the joint-limit rows when infeasible [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.fingertip_workspace_weight',
        DOUBLE,
        1.0e3,
        'Penalty on the squared slack of the fingertip-workspace rows when infeasible [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.object_workspace_weight',
        DOUBLE,
        1.0e3,
        'Penalty on the squared slack of the object-workspace rows when infeasible [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'relaxation.torque_rate_weight',
        DOUBLE,
        1.0e3,
        'Penalty on the squared slack of the torque-rate rows when infeasible (at most '
        'every safety weight) [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.eps_abs',
        DOUBLE,
        1.0e-4,
        'OSQP absolute tolerance [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.eps_rel',
        DOUBLE,
        1.0e-4,
        'OSQP relative tolerance [-]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'osqp.max_iter',
        INTEGER,
        50,
        'OSQP iteration limit per solve (at most 100000, about 0.1 s per tick) [-]',
        min_value=1,
        max_value=MAX_OSQP_ITERATIONS,
    ),
    ParameterSpec(
        'osqp.polish',
        BOOL,
        False,
        'Polish the OSQP solution (active-set refinement; the filter refines it exactly anyway)',
    ),
    ParameterSpec(
        'qp.solver',
        STRING,
        'osqp',
        'QP backend: osqp (ADMM, certified or refined exactly) or daqp (dual active set)',
        choices=('osqp', 'daqp'),
    ),
    ParameterSpec(
        'qp.metric',
        STRING,
        'identity',
        "Cost of the correction du = u - u_nom: identity ||du||^2 (the paper's) or "
        'inverse_inertia du^T W du, W = (tr(M_h)/m) M_h^-1 (the kinetic-energy norm of the '
        'joint acceleration du excites; relaxation slack then in W distance)',
        choices=QP_METRICS,
    ),
)
"""The safety filter's own parameters (read by ``SafetyFilterConfig``)."""

SAFETY_FILTER_INPUT_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'input.max_age',
        DOUBLE,
        0.05,
        'State or nominal command older than this is stale and rejected [s]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'input.hold_timeout',
        DOUBLE,
        0.1,
        'After rejected input, hold the last safe command this long, then fall back [s]',
        min_value=0.0,
        exclusive_min=True,
    ),
    ParameterSpec(
        'input.fallback',
        STRING,
        'gravity_compensation',
        'Command after the hold timeout: zero torque or gravity_compensation',
        choices=('zero', 'gravity_compensation'),
    ),
)
"""How the safety filter node treats stale or invalid input (``InputPolicyConfig``)."""

SAFETY_FILTER_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'enabled',
        BOOL,
        True,
        'Filter on; false passes u_nom through unchanged (still validated), e.g. for the '
        "paper's nominal run",
    ),
    *SAFETY_FILTER_QP_PARAMETERS,
    *SAFETY_FILTER_INPUT_PARAMETERS,
    *GRASP_CHECK_PARAMETERS,
    ParameterSpec(
        'diagnostics.period',
        DOUBLE,
        0.1,
        'Least stamp interval between two /diagnostics statuses of unchanged good ticks '
        '(solved, nominal, off); every other tick is published; 0: every tick [s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'margins.period',
        DOUBLE,
        0.0,
        'Least stamp interval between two /safety_filter/margins messages; 0: every tick [s]',
        min_value=0.0,
    ),
)

HAND_SIM_NODE = 'hand_sim_node'
NOMINAL_CONTROLLER_NODE = 'nominal_controller_node'
SAFETY_FILTER_NODE = 'safety_filter_node'

NODE_SCHEMAS: dict[str, NodeSchema] = {
    HAND_SIM_NODE: NodeSchema.from_sections(HAND_SIM_NODE, MODEL_PARAMETERS, HAND_SIM_PARAMETERS),
    NOMINAL_CONTROLLER_NODE: NodeSchema.from_sections(
        NOMINAL_CONTROLLER_NODE,
        MODEL_PARAMETERS,
        NOMINAL_CONTROLLER_PARAMETERS,
        GRASP_CHECK_PARAMETERS,
    ),
    SAFETY_FILTER_NODE: NodeSchema.from_sections(
        SAFETY_FILTER_NODE, MODEL_PARAMETERS, SAFETY_FILTER_PARAMETERS
    ),
}


# --------------------------------------------------------------------------------------------
# Checks across parameters (values only: no URDF, no geometry)
# --------------------------------------------------------------------------------------------


def _values(value: Any) -> list[Any]:
    """Return a per-contact parameter's values: ``[value]`` for one, else the list."""
    return list(value) if isinstance(value, list | tuple) else [value]


def check_model_parameters(values: Mapping[str, Any], source: str = 'parameters') -> None:
    """Check the model section for consistency between its own parameters.

    - each per-contact parameter has one value or one per contact;
    - each workspace interval is non-empty: ``a_min < a_max``, ``b_min < b_max`` (per
      contact);
    - joint names, fingertip frames and contact names are non-empty and unique;
    - one fingertip frame per contact name and, for a box or cube, one face per contact (or
      one face entry for all).

    Raises:
        ParameterError: Listing every violation, each naming the parameters and values.
    """
    errors: list[str] = []
    contacts = len(values['model.contact_names'])
    per_contact = {spec.name: values[spec.name] for spec in MODEL_PARAMETERS if spec.per_contact}
    for name, value in per_contact.items():
        count = len(_values(value))
        if count not in (1, contacts):
            errors.append(
                f"parameter '{name}': expected 1 or {contacts} values (one for every contact or "
                f"one per contact in 'model.contact_names'), got {count}"
            )
    prefix = 'model.fingertip_workspace.'
    for coordinate in ('a', 'b'):
        low, high = values[f'{prefix}{coordinate}_min'], values[f'{prefix}{coordinate}_max']
        lows, highs = _values(low), _values(high)
        if len(lows) not in (1, contacts) or len(highs) not in (1, contacts):
            continue
        count = max(len(lows), len(highs))
        pairs = zip(lows * (count // len(lows)), highs * (count // len(highs)), strict=True)
        per_contact_given = count > 1
        for index, (lo, hi) in enumerate(pairs):
            if not lo < hi:
                where = f' element {index}' if per_contact_given else ''
                errors.append(
                    f"parameters '{prefix}{coordinate}_min' and '{prefix}{coordinate}_max'"
                    f'{where}: expected {coordinate}_min < {coordinate}_max, got {lo!r} and '
                    f'{hi!r}'
                )
    for name in ('model.joint_names', 'model.fingertip_frames', 'model.contact_names'):
        items = list(values[name])
        duplicates = sorted({item for item in items if items.count(item) > 1})
        if not items:
            errors.append(f"parameter '{name}': expected at least one name, got []")
        elif duplicates:
            errors.append(f"parameter '{name}': expected unique names, got {duplicates} twice")
    lists = ['model.fingertip_frames']
    if values['model.object.shape'] != 'sphere' and len(values['model.contact_faces']) != 1:
        lists.append('model.contact_faces')
    for name in lists:
        if len(values[name]) != contacts:
            errors.append(
                f"parameter '{name}': expected one entry per contact in 'model.contact_names' "
                f'({contacts}), got {len(values[name])}'
            )
    raise_parameter_errors(source, errors, 'inconsistent')


def check_hand_sim_parameters(values: Mapping[str, Any], source: str = 'parameters') -> None:
    """Check the simulator's initial state against the model section.

    - one initial joint angle per joint of ``model.joint_names``;
    - the initial orientation is a unit quaternion (to 1e-6).

    Raises:
        ParameterError: Listing every violation.
    """
    errors: list[str] = []
    joints = len(values['model.joint_names'])
    positions = values['initial.joint_positions']
    if len(positions) != joints:
        errors.append(
            f"parameter 'initial.joint_positions': expected one angle per joint in "
            f"'model.joint_names' ({joints}), got {len(positions)}"
        )
    norm = math.sqrt(sum(x * x for x in values['initial.object_orientation']))
    if abs(norm - 1.0) > 1e-6:
        errors.append(
            "parameter 'initial.object_orientation': expected a unit quaternion (norm 1 to "
            f'1e-6), got norm {norm!r}'
        )
    raise_parameter_errors(source, errors, 'inconsistent')


_NODE_CHECKS: dict[str, tuple[Callable[[Mapping[str, Any], str], None], ...]] = {
    HAND_SIM_NODE: (check_model_parameters, check_hand_sim_parameters),
    NOMINAL_CONTROLLER_NODE: (check_model_parameters,),
    SAFETY_FILTER_NODE: (check_model_parameters,),
}


def check_node_parameters(
    node_name: str, values: Mapping[str, Any], source: str = 'parameters'
) -> None:
    """Run every cross-parameter check of ``node_name`` on its validated values."""
    for check in _NODE_CHECKS[node_name]:
        check(values, source)


def load_node_parameters(
    path: str | Path,
    node_name: str,
    namespace: str = '/',
    overrides: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Load everything a node gets from a parameter file, as the ROS-free runner needs it.

    Reads the file, merges ``/**`` and the node's section, validates against the node's
    schema (defaults filled in), runs the cross-parameter checks and resolves relative
    paths against the file's directory.

    Args:
        path: A ROS 2 parameter file, e.g. ``config/paper_scenario.yaml``.
        node_name: A key of :data:`NODE_SCHEMAS`.
        namespace: The node's namespace (for files that address namespaced nodes).
        overrides: ``{dotted name: value}`` replacing the file's values (as ``--ros-args -p``
            does); each must be a parameter of this node.

    Raises:
        ParameterError: The message names the file, the node and each bad parameter.
        KeyError: ``node_name`` is not one of the package's nodes.
    """
    if node_name not in NODE_SCHEMAS:
        raise KeyError(f"unknown node '{node_name}': expected one of {sorted(NODE_SCHEMAS)}")
    schema = NODE_SCHEMAS[node_name]
    source = f"parameter file '{path}' (node '{node_name}')"
    if overrides:
        source += f' with overrides {dict(overrides)}'
    file_parameters = load_parameter_file(path)
    # A misspelt section would leave its node at the defaults unseen: refused, as by the nodes.
    raise_parameter_errors(source, misspelt_node_sections(file_parameters, NODE_SCHEMAS))
    given = {**parameters_for_node(file_parameters, node_name, namespace), **(overrides or {})}
    values = validate_parameters(
        schema,
        given,
        source,
        other_schemas=[other for name, other in NODE_SCHEMAS.items() if name != node_name],
    )
    check_node_parameters(node_name, values, source)
    from grasp_safety_filter.io.required_parameters import check_required_parameters

    own_section = any(key.rsplit('/', 1)[-1] == node_name for key in file_parameters)
    check_required_parameters(node_name, given, source, own_section)
    return resolve_relative_paths(schema, values, Path(path).resolve().parent)


# --------------------------------------------------------------------------------------------
# Documentation
# --------------------------------------------------------------------------------------------


def _markdown_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, list):
        return '[' + ', '.join(_markdown_value(item) for item in value) + ']'
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def parameter_table_markdown(schema: Iterable[ParameterSpec]) -> str:
    """Render parameters as a Markdown table: name, type, default, admissible, description.

    Read-only parameters (read once at start-up) are marked with ``(ro)``.
    """
    lines = [
        '| Parameter | Type | Default | Admissible | Description |',
        '|---|---|---|---|---|',
    ]
    for spec in schema:
        cells = [
            f'`{spec.name}`' + (' (ro)' if spec.read_only else ''),
            spec.type.value,
            f'`{_markdown_value(spec.default)}`',
            spec.constraint_text() or 'any',
            spec.description,
        ]
        lines.append('| ' + ' | '.join(cell.replace('|', '\\|') for cell in cells) + ' |')
    return '\n'.join(lines) + '\n'
