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

``STREAM_PARAMETERS`` (:mod:`.inputs`: how the inputs make a tick) belong to both
controllers, ``COMMAND_PARAMETERS`` to the safety filter.

Modules: :mod:`.common`, :mod:`.model`, :mod:`.hand_sim`, :mod:`.nominal`,
:mod:`.safety_filter`, :mod:`.inputs`, :mod:`.nodes` (schemas, cross-parameter checks,
loading) and :mod:`.overrides` (overrides for every node or for one, ``NODE/NAME``); this
package re-exports what the rest of the package uses.
"""

from __future__ import annotations

from grasp_safety_filter.io.schemas.common import (  # noqa: F401
    EXPECTED_OUTCOMES,
    NO_OUTCOME,
    PAPER_OUTCOME,
)
from grasp_safety_filter.io.schemas.hand_sim import (  # noqa: F401
    command_delay_steps,
    driver_substeps,
    HAND_SIM_PARAMETERS,
    hardware_parameter_errors,
    ZERO_TORQUE,
)
from grasp_safety_filter.io.schemas.inputs import (  # noqa: F401
    COMMAND_PARAMETERS,
    EXACT_SYNC,
    FLOAT64_MULTI_ARRAY_COMMAND,
    JOINT_STATE_COMMAND,
    LATEST_SYNC,
    MODEL_JOINT_ORDER,
    model_joint_order,
    ODOMETRY_MESSAGE,
    POSE_MESSAGE,
    STREAM_PARAMETERS,
)
from grasp_safety_filter.io.schemas.markers import MARKER_PARAMETERS  # noqa: F401
from grasp_safety_filter.io.schemas.model import (  # noqa: F401
    MODEL_PARAMETERS,
    REQUIRED_MODEL_PARAMETERS,
)
from grasp_safety_filter.io.schemas.nodes import (  # noqa: F401
    check_hand_sim_parameters,
    check_model_parameters,
    check_node_parameters,
    GRASP_MARKERS_NODE,
    HAND_SIM_NODE,
    load_node_parameters,
    NODE_SCHEMAS,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.io.schemas.nominal import (  # noqa: F401
    GRASP_CHECK_GAP_TOLERANCE,
    GRASP_CHECK_PARAMETERS,
    NOMINAL_CONTROLLER_PARAMETERS,
)
from grasp_safety_filter.io.schemas.overrides import (  # noqa: F401
    node_overrides,
    override_errors,
)
from grasp_safety_filter.io.schemas.safety_filter import (  # noqa: F401
    SAFETY_FILTER_PARAMETERS,
    SAFETY_FILTER_QP_PARAMETERS,
)
