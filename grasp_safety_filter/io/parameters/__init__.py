"""Parameter schemas: one typed, documented, range-checked entry per ROS parameter.

The same schema is declared by the rclpy node (with ParameterDescriptors and an on-set
validation callback) and used by the ROS-free runner to load ``config/*.yaml``.

A ROS 2 parameter file maps node names to ``ros__parameters``::

    /**:                          # every node
      ros__parameters:
        model:
          fingertip_radius: 0.06  # nested mappings flatten to "model.fingertip_radius"
    hand_sim_node:                # the node /hand_sim_node
      ros__parameters:
        time_step: 0.001

Node names may carry a leading slash and a namespace (``/arm/hand_sim_node``), or nest the
namespace as a mapping (``arm: {hand_sim_node: {ros__parameters: ...}}``); ``/*`` matches
one name token and ``/**`` any number. Sections apply in file order, later values replacing
earlier ones, as in rclpy: put ``/**`` first. Parameter types are static, as in ROS:
``1`` is an integer and is not accepted where a double is declared (write ``1.0``).

Only :func:`declare_node_parameters`, :func:`make_parameter_descriptor` and
:func:`on_set_parameters_callback` touch ROS, and they import it when called.

Modules: :mod:`.spec` (types, specs, node schemas), :mod:`.files` (reading files),
:mod:`.validation`, :mod:`.rclpy_glue`; this package re-exports their public names.
"""

from __future__ import annotations

from grasp_safety_filter.io.parameters.files import (  # noqa: F401
    flatten_parameters,
    load_parameter_file,
    misspelt_node_sections,
    parameters_for_node,
    parse_parameter_value,
)
from grasp_safety_filter.io.parameters.rclpy_glue import (  # noqa: F401
    declare_node_parameters,
    make_parameter_descriptor,
    on_set_parameters_callback,
)
from grasp_safety_filter.io.parameters.spec import (  # noqa: F401
    NodeSchema,
    ParameterError,
    ParameterSpec,
    ParameterType,
    ROS_PARAMETERS_KEY,
    suggestion,
    WILDCARD_NODE,
)
from grasp_safety_filter.io.parameters.validation import (  # noqa: F401
    raise_parameter_errors,
    resolve_relative_paths,
    validate_parameters,
)
