"""``MODEL_PARAMETERS``: the hand, the object and their contacts, shared by all nodes (``/**``)."""

from __future__ import annotations

import math

from grasp_safety_filter.io.parameters import (
    ParameterSpec,
)
from grasp_safety_filter.io.schemas.common import (
    CUBE_FACES,
    DOUBLE,
    DOUBLE_ARRAY,
    FINGERTIP_WORKSPACE_A_MARGIN,
    HALF_PI,
    NEAREST_FACE,
    PAPER_JOINT_NAMES,
    STRING,
    STRING_ARRAY,
)

# fmt: off
MODEL_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'model.urdf_file', STRING, 'hand.urdf',
        "Hand URDF; a relative path resolves against the parameter file's directory",
        read_only=True, is_path=True, required=True,
    ),
    ParameterSpec(
        'model.joint_names', STRING_ARRAY, PAPER_JOINT_NAMES,
        'Actuated URDF joints, in the order of every joint vector and torque command',
        read_only=True, required=True,
    ),
    ParameterSpec(
        'model.fingertip_frames', STRING_ARRAY, ['finger1_tip', 'finger2_tip', 'finger3_tip'],
        'URDF frames of the fingertips, one per contact (z out of the tip); each fingertip is '
        "the <collision><sphere> on its frame's link (or a link fixed to it): radius R_i, and "
        "its centre the fingertip frame's origin",
        read_only=True, required=True,
    ),
    ParameterSpec(
        'model.contact_names', STRING_ARRAY, ['finger1', 'finger2', 'finger3'],
        'Contact labels, one per fingertip frame (topics, diagnostics, figures)',
        read_only=True, required=True,
    ),
    ParameterSpec(
        'model.fingertip_radius', DOUBLE, 0.0,
        'Deprecated check: 0 (default): each R_i from its collision sphere; > 0: every '
        'fingertip collision sphere must have this radius [m]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'model.object.shape', STRING, 'cube',
        'Shape of the grasped object (a box of three edge lengths, a cube, a sphere)',
        choices=('cube', 'box', 'sphere'), read_only=True, required=True,
    ),
    ParameterSpec(
        'model.object.mass', DOUBLE, 0.11,
        'Mass of the object [kg]',
        min_value=0.0, exclusive_min=True, read_only=True, required=True,
    ),
    ParameterSpec(
        'model.object.size', DOUBLE, 0.2604,
        'Cube edge length or sphere diameter; required for a cube or a sphere [m]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'model.object.edge_lengths', DOUBLE_ARRAY, [0.2604, 0.2604, 0.2604],
        'Box edge lengths along the object frame O (x, y, z); required for a box [m]',
        min_value=0.0, exclusive_min=True, length=3, read_only=True,
    ),
    ParameterSpec(
        'model.contact_faces', STRING_ARRAY, [NEAREST_FACE],
        "Box face (outward normal in the object frame O) of each contact, or 'nearest': the "
        'face nearest the fingertip at the first state; a declared face must be that one; one '
        'entry applies to every contact; ignored for a sphere',
        choices=(*CUBE_FACES, NEAREST_FACE), read_only=True,
    ),
    ParameterSpec(
        'model.friction_coefficient', DOUBLE, 0.9,
        'Coulomb friction coefficient mu between fingertips and object: one for every '
        'contact or a list of one per contact, in model.contact_names order [-]',
        min_value=0.0, exclusive_min=True, read_only=True, per_contact=True, required=True,
    ),
    ParameterSpec(
        'model.torsional_friction', DOUBLE, 0.0,
        'Torsional friction mu_t of the fingertips: 0, point contacts with friction (the '
        "paper's model: no torque about the contact normal, the fingertip spins freely); > 0, "
        'soft fingers: each contact also transmits a torque about its normal, |tau_n| <= '
        'mu_t f_n, and the fingertip does not spin on the object (MuJoCo condim 4; its default '
        'is 0.005 m); one for every contact or a list of one per contact, all 0 or all > 0 [m]',
        min_value=0.0, read_only=True, per_contact=True,
    ),
    ParameterSpec(
        'model.torsional_compliance', DOUBLE, 0.1,
        "Soft fingers' relative torsional compliance rho: each no-spin constraint is solved "
        "with its diagonal of B_ho times 1 + rho, as MuJoCo's soft constraints (about 0.11 at "
        'its default impedance); 0: rigid. Where the fingers can hardly twist about their '
        'contact normals (the paper hand) the rigid torsions are large and jump, and the '
        'filter cannot keep them bounded; ignored for point contacts [-]',
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'model.gravity', DOUBLE_ARRAY, [0.0, 0.0, -9.81],
        'Gravitational acceleration in the palm frame P (x, y, z) [m/s^2]',
        length=3, read_only=True,
    ),
    ParameterSpec(
        'model.palm_frame', STRING, '',
        "Palm frame P: the URDF's root link when empty; the frame_id of /object/odom and "
        '/object/reference (checked on receipt)',
        read_only=True,
    ),
    ParameterSpec(
        'model.object_frame', STRING, 'object',
        'Object frame O: the child_frame_id of /object/odom (checked on receipt)',
        read_only=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.a_min', DOUBLE, -HALF_PI + FINGERTIP_WORKSPACE_A_MARGIN,
        'Lower bound of the fingertip contact coordinate a: one for every contact or a '
        'list of one per contact [rad]',
        min_value=-HALF_PI, max_value=HALF_PI, read_only=True, per_contact=True, required=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.a_max', DOUBLE, HALF_PI - FINGERTIP_WORKSPACE_A_MARGIN,
        'Upper bound of the fingertip contact coordinate a: one for every contact or a '
        'list of one per contact [rad]',
        min_value=-HALF_PI, max_value=HALF_PI, read_only=True, per_contact=True, required=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.b_min', DOUBLE, -math.pi,
        'Lower bound of the fingertip contact coordinate b: one for every contact or a '
        'list of one per contact [rad]',
        min_value=-math.pi, max_value=0.0, read_only=True, per_contact=True, required=True,
    ),
    ParameterSpec(
        'model.fingertip_workspace.b_max', DOUBLE, 0.0,
        'Upper bound of the fingertip contact coordinate b: one for every contact or a '
        'list of one per contact [rad]',
        min_value=-math.pi, max_value=0.0, read_only=True, per_contact=True, required=True,
    ),
)
# fmt: on

#: The model parameters that describe the hand and the object: every scenario gives them
#: (with the object's dimensions for its shape: ``required_model_parameters``).
REQUIRED_MODEL_PARAMETERS = tuple(spec.name for spec in MODEL_PARAMETERS if spec.required)
