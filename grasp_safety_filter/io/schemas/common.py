"""What the node schemas share: parameter types, limits, the paper's names, expected outcomes."""

from __future__ import annotations

import math

from grasp_safety_filter.io.parameters import (
    ParameterType,
)

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
