"""The node schemas, the checks across their parameters, and loading a node's parameters."""

from __future__ import annotations

from collections.abc import Callable, Mapping
import math
from pathlib import Path
from typing import Any

from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    misspelt_node_sections,
    NodeSchema,
    parameters_for_node,
    raise_parameter_errors,
    resolve_relative_paths,
    validate_parameters,
)
from grasp_safety_filter.io.schemas.hand_sim import (
    HAND_SIM_PARAMETERS,
    hardware_parameter_errors,
)
from grasp_safety_filter.io.schemas.inputs import (
    check_command_parameters,
    check_stream_parameters,
    COMMAND_PARAMETERS,
    STREAM_PARAMETERS,
)
from grasp_safety_filter.io.schemas.markers import MARKER_PARAMETERS
from grasp_safety_filter.io.schemas.model import MODEL_PARAMETERS
from grasp_safety_filter.io.schemas.nominal import (
    GRASP_CHECK_PARAMETERS,
    NOMINAL_CONTROLLER_PARAMETERS,
)
from grasp_safety_filter.io.schemas.safety_filter import SAFETY_FILTER_PARAMETERS

HAND_SIM_NODE = 'hand_sim_node'
NOMINAL_CONTROLLER_NODE = 'nominal_controller_node'
SAFETY_FILTER_NODE = 'safety_filter_node'
GRASP_MARKERS_NODE = 'grasp_markers_node'

NODE_SCHEMAS: dict[str, NodeSchema] = {
    HAND_SIM_NODE: NodeSchema.from_sections(HAND_SIM_NODE, MODEL_PARAMETERS, HAND_SIM_PARAMETERS),
    NOMINAL_CONTROLLER_NODE: NodeSchema.from_sections(
        NOMINAL_CONTROLLER_NODE,
        MODEL_PARAMETERS,
        NOMINAL_CONTROLLER_PARAMETERS,
        GRASP_CHECK_PARAMETERS,
        STREAM_PARAMETERS,
    ),
    SAFETY_FILTER_NODE: NodeSchema.from_sections(
        SAFETY_FILTER_NODE,
        MODEL_PARAMETERS,
        SAFETY_FILTER_PARAMETERS,
        STREAM_PARAMETERS,
        COMMAND_PARAMETERS,
    ),
    GRASP_MARKERS_NODE: NodeSchema.from_sections(
        GRASP_MARKERS_NODE, MODEL_PARAMETERS, MARKER_PARAMETERS
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
    - the initial orientation is a unit quaternion (to 1e-6);
    - with ``lockstep`` false, the hardware mode's parameters together
      (:func:`~grasp_safety_filter.io.schemas.hand_sim.hardware_parameter_errors`).

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
    errors += hardware_parameter_errors(values)
    raise_parameter_errors(source, errors, 'inconsistent')


_NODE_CHECKS: dict[str, tuple[Callable[[Mapping[str, Any], str], None], ...]] = {
    HAND_SIM_NODE: (check_model_parameters, check_hand_sim_parameters),
    NOMINAL_CONTROLLER_NODE: (check_model_parameters, check_stream_parameters),
    SAFETY_FILTER_NODE: (
        check_model_parameters,
        check_stream_parameters,
        check_command_parameters,
    ),
    GRASP_MARKERS_NODE: (check_model_parameters,),
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
