"""``HAND_SIM_PARAMETERS``: the simulator's own parameters (initial grasp, integration, run).

``hardware.*`` and ``tracker.*`` configure the hardware mode (``lockstep: false``): a hand's
driver and an object tracker emulated on the wall clock (:mod:`hand_sim_node.hardware`).
:func:`hardware_parameter_errors` checks them against each other and ``time_step``;
:func:`command_delay_steps` the lockstep mode's ``command_delay`` against ``time_step``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from grasp_safety_filter.io.parameters import (
    ParameterError,
    ParameterSpec,
)
from grasp_safety_filter.io.plant_schema import PLANT_PARAMETERS
from grasp_safety_filter.io.schemas.common import (
    BOOL,
    DOUBLE,
    DOUBLE_ARRAY,
    EXPECTED_OUTCOMES,
    INTEGER,
    NO_OUTCOME,
    PAPER_FINGER_JOINT_POSITIONS,
    STRING,
    STRING_ARRAY,
)
from grasp_safety_filter.io.schemas.inputs import (
    COMMAND_MESSAGES,
    joint_order_errors,
    JOINT_STATE_COMMAND,
    MODEL_JOINT_ORDER,
    OBJECT_MESSAGES,
    ODOMETRY_MESSAGE,
)

#: ``hardware.timeout_torque`` values: g(q) of our model at the plant's q, or no torque.
GRAVITY_COMPENSATION = 'gravity_compensation'
ZERO_TORQUE = 'zero'
TIMEOUT_TORQUES = (GRAVITY_COMPENSATION, ZERO_TORQUE)

#: Relative tolerance on a driver period being a whole number of ``time_step``.
PERIOD_TOLERANCE = 1e-9

#: Most joints of an arm the hardware mode can put before the hand's.
MAX_EXTRA_JOINTS = 1000

# fmt: off
HAND_SIM_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'initial.joint_positions', DOUBLE_ARRAY, PAPER_FINGER_JOINT_POSITIONS * 3,
        'Joint angles q(0) of the initial static grasp, in model.joint_names order [rad]',
        read_only=True, required=True,
    ),
    ParameterSpec(
        'initial.object_position', DOUBLE_ARRAY, [0.0, 0.0, 0.3],
        'Object centre p_o(0) in the palm frame P (x, y, z) [m]',
        length=3, read_only=True, required=True,
    ),
    ParameterSpec(
        'initial.object_orientation', DOUBLE_ARRAY, [0.0, 0.0, 0.0, 1.0],
        'Object orientation R_po(0) as a unit quaternion (x, y, z, w) [-]',
        length=4, min_value=-1.0, max_value=1.0, read_only=True,
    ),
    ParameterSpec(
        'integrator', STRING, 'ode3',
        "Fixed-step integrator: ode3 (Bogacki-Shampine, the paper's) or rk4",
        choices=('ode3', 'rk4'), read_only=True,
    ),
    ParameterSpec(
        'time_step', DOUBLE, 0.001,
        'Integration and control period (stamps are whole nanoseconds) [s]',
        min_value=1e-9, read_only=True,
    ),
    ParameterSpec(
        'duration', DOUBLE, 15.0,
        'Simulated time after which the run ends [s]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'stop_on_slip', BOOL, False,
        "End the run when a contact's required friction beta exceeds mu",
    ),
    ParameterSpec(
        'stop_on_workspace_exit', BOOL, True,
        'End the run when a contact point leaves the fingertip workspace',
    ),
    ParameterSpec(
        'expected_outcome', STRING, NO_OUTCOME,
        'Published outcome the scenario must reproduce, checked by grasp-demo and grasp-analyze '
        '(exit code 1 if not): "paper" (Shaw-Cortez et al. 2018, Sec. IV: the nominal run '
        'slips, passes a joint limit, then stops on leaving the fingertip workspace; the '
        'filtered run holds to the end, nothing violated) or "none"; unused by the simulator',
        choices=EXPECTED_OUTCOMES, read_only=True,
    ),
    ParameterSpec(
        'stabilization.position_gain', DOUBLE, 2500.0,
        'Baumgarte gain on the contact-constraint position drift [1/s^2]',
        min_value=0.0,
    ),
    ParameterSpec(
        'stabilization.velocity_gain', DOUBLE, 100.0,
        'Baumgarte gain on the contact-constraint velocity drift [1/s]',
        min_value=0.0,
    ),
    ParameterSpec(
        'lockstep', BOOL, True,
        'True: integrate to t_k+1 only after the command stamped t_k arrives (simulation '
        "time, /clock); false: hardware mode, free-running on the wall clock as a hand's "
        'driver (hardware.*) and an object tracker (tracker.*) do, use_sim_time false',
        read_only=True,
    ),
    ParameterSpec(
        'command_timeout', DOUBLE, 1.0,
        'Lockstep: wall-clock wait for the command stamped t_k before a diagnostic [s]',
        min_value=0.0, exclusive_min=True,
    ),
    ParameterSpec(
        'command_delay', DOUBLE, 0.0,
        'Lockstep: actuator or communication delay; the plant applies the command stamped t_k '
        'from t_k + command_delay on, a whole number of time_step (0: from t_k); until the '
        'first delayed command is due it applies the first command it received. The hardware '
        'mode (lockstep false) takes none: 0 [s]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'publish_clock', BOOL, True,
        'Publish the simulation time on /clock (for nodes with use_sim_time)',
        read_only=True,
    ),
    ParameterSpec(
        'start.wait_for_recorder', STRING, '',
        'Start only once this node (e.g. rosbag2_recorder) subscribes to every published '
        'topic of the topic table; empty: do not wait',
        read_only=True,
    ),
    *PLANT_PARAMETERS,
    ParameterSpec(
        'hardware.rate', DOUBLE, 1000.0,
        "Hardware mode: the driver's rate; every 1/rate s of wall time the plant is integrated "
        'by 1/rate s, a whole number of time_step, and its joint states published [Hz]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'hardware.command_timeout', DOUBLE, 0.1,
        'Hardware mode: wall-clock time without a valid command after which the plant gets '
        'hardware.timeout_torque and /diagnostics an ERROR, until commands resume [s]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'hardware.timeout_torque', STRING, GRAVITY_COMPENSATION,
        'Hardware mode: torque applied while commands are timed out: gravity_compensation '
        "(g(q) of the model at the plant's q) or zero",
        choices=TIMEOUT_TORQUES, read_only=True,
    ),
    ParameterSpec(
        'hardware.command_message', STRING, JOINT_STATE_COMMAND,
        'Hardware mode: command input, joint_state (sensor_msgs/JointState by joint name on '
        '/hand/effort_command, any stamp) or float64_multi_array (std_msgs/Float64MultiArray '
        'on /effort_controller/commands, in hardware.command_joints order)',
        choices=COMMAND_MESSAGES, read_only=True,
    ),
    ParameterSpec(
        'hardware.command_joints', STRING_ARRAY, [MODEL_JOINT_ORDER],
        "Hardware mode, float64_multi_array: the effort controller's joints, every model joint "
        "once, in its order ('model.joint_names': in that order)",
        read_only=True,
    ),
    ParameterSpec(
        'hardware.extra_joints', INTEGER, 0,
        'Hardware mode: joints of an arm, arm_joint_1..., published first in '
        '/hand/joint_states at fixed positions, as a joint_state_broadcaster does [-]',
        min_value=0, max_value=MAX_EXTRA_JOINTS, read_only=True,
    ),
    ParameterSpec(
        'tracker.rate', DOUBLE, 100.0,
        "Hardware mode: rate of the emulated object tracker's pose samples, at most "
        'hardware.rate [Hz]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'tracker.latency', DOUBLE, 0.01,
        "Hardware mode: delay from a tracker sample's capture (its stamp) to its publication, "
        'released at the first driver period at or after it [s]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'tracker.position_noise', DOUBLE, 0.0005,
        "Hardware mode: standard deviation of the tracker's position noise, per palm axis [m]",
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'tracker.orientation_noise', DOUBLE, 0.005,
        "Hardware mode: standard deviation of the tracker's orientation noise per axis, "
        'applied as exp3(noise) R in the palm frame [rad]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'tracker.message', STRING, ODOMETRY_MESSAGE,
        'Hardware mode: tracker output, odometry (nav_msgs/Odometry on /object/odom, with '
        'the true twist) or pose (geometry_msgs/PoseStamped on /object/pose)',
        choices=OBJECT_MESSAGES, read_only=True,
    ),
    ParameterSpec(
        'tracker.seed', INTEGER, 0,
        "Hardware mode: seed of the tracker's noise [-]",
        min_value=0, read_only=True,
    ),
)
# fmt: on


def driver_substeps(rate: float, time_step: float) -> int:
    """Return the integration steps of ``time_step`` s in one driver period of ``rate`` Hz.

    Raises:
        ParameterError: ``1 / rate`` is not a whole number (>= 1) of ``time_step`` to
            :data:`PERIOD_TOLERANCE`, naming both parameters.
    """
    steps = 1.0 / (rate * time_step)
    whole = round(steps)
    if whole < 1 or abs(steps - whole) > PERIOD_TOLERANCE * steps:
        raise ParameterError(
            f"parameters 'hardware.rate' and 'time_step': expected the driver period "
            f'1/hardware.rate to be a whole number of time_step, got hardware.rate = {rate!r} '
            f'Hz (period {1.0 / rate!r} s) and time_step = {time_step!r} s ({steps:.9g} '
            'steps); e.g. hardware.rate = 1/(n time_step)'
        )
    return whole


def command_delay_steps(delay: float, time_step: float) -> int:
    """Return the steps of ``time_step`` s in ``command_delay`` (``delay`` s, >= 0).

    Raises:
        ParameterError: ``delay`` is not a whole number of ``time_step`` to
            :data:`PERIOD_TOLERANCE`, naming both parameters.
    """
    steps = delay / time_step
    whole = round(steps)
    if abs(steps - whole) > PERIOD_TOLERANCE * max(steps, 1.0):
        raise ParameterError(
            f"parameters 'command_delay' and 'time_step': expected the delay to be a whole "
            f'number of time_step, got command_delay = {delay!r} s and time_step = '
            f'{time_step!r} s ({steps:.9g} steps); e.g. command_delay = n time_step'
        )
    return whole


def hardware_parameter_errors(values: Mapping[str, Any]) -> list[str]:
    """Return what is wrong with the hardware mode's parameters together (empty: nothing).

    Checked only with ``lockstep`` false (the lockstep mode does not read them): the driver
    period is a whole number of ``time_step`` (:func:`driver_substeps`), the tracker is not
    faster than the driver, and ``hardware.command_joints`` names every model joint once.
    """
    if values['lockstep']:
        return []
    errors: list[str] = []
    rate = values['hardware.rate']
    try:
        driver_substeps(rate, values['time_step'])
    except ParameterError as error:
        errors.append(str(error))
    if values['tracker.rate'] > rate:
        errors.append(
            f"parameters 'tracker.rate' and 'hardware.rate': expected a tracker no faster than "
            f"the driver (it samples the driver's states), got {values['tracker.rate']!r} Hz "
            f'and {rate!r} Hz'
        )
    errors += joint_order_errors(
        'hardware.command_joints', values['hardware.command_joints'], values['model.joint_names']
    )
    return errors
