"""``HAND_SIM_PARAMETERS``: the simulator's own parameters (initial grasp, integration, run)."""

from __future__ import annotations

from grasp_safety_filter.io.parameters import (
    ParameterSpec,
)
from grasp_safety_filter.io.plant_schema import PLANT_PARAMETERS
from grasp_safety_filter.io.schemas.common import (
    BOOL,
    DOUBLE,
    DOUBLE_ARRAY,
    EXPECTED_OUTCOMES,
    NO_OUTCOME,
    PAPER_FINGER_JOINT_POSITIONS,
    STRING,
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
