"""Parameters without a meaningful default: a node refuses to start unless they are given.

They are the specs marked ``required``. The ``model.*`` ones describe the hand and the
object, and every node needs them: their schema defaults are the paper's hand's, which would
silently describe another hand (a 6 cm fingertip on a 12 mm one). The initial grasp of
``hand_sim_node`` (``initial.joint_positions``, ``initial.object_position``) is the hand's
own too, so a scenario file without it is refused, by the ROS-free loader and by the node,
with a message naming the section.

Every other parameter keeps its documented default when no file section gives it: the
nominal controller's gains and the safety filter's settings are the paper's and do not
depend on the hand's geometry, and a filter run on a real hand with only the shared ``/**``
section (README, "Using your own hand") is the intended use.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import NODE_SCHEMAS, REQUIRED_MODEL_PARAMETERS


def required_model_parameters(given: Mapping[str, Any]) -> tuple[str, ...]:
    """:data:`REQUIRED_MODEL_PARAMETERS` and the object's dimensions for its given shape."""
    shape = given.get('model.object.shape')
    if shape == 'box':
        return (*REQUIRED_MODEL_PARAMETERS, 'model.object.edge_lengths')
    if shape in ('cube', 'sphere'):
        return (*REQUIRED_MODEL_PARAMETERS, 'model.object.size')
    return REQUIRED_MODEL_PARAMETERS


def check_required_parameters(
    node_name: str,
    given: Mapping[str, Any] | Iterable[str],
    source: str,
    has_own_section: bool | None = None,
) -> None:
    """Raise ParameterError unless every required parameter is given: the model's first.

    Args:
        node_name: The node's schema name, e.g. ``"hand_sim_node"``.
        given: The parameters (name: value, or names) the files and the command line give
            the node.
        source: Where they come from (file and node), prefixed to the message.
        has_own_section: Whether a file has a section for this very node (None: unknown).
    """
    values = given if isinstance(given, Mapping) else dict.fromkeys(given)
    missing_model = [name for name in required_model_parameters(values) if name not in values]
    if missing_model:
        quoted = ', '.join(f"'{name}'" for name in missing_model)
        raise ParameterError(
            f'{source}: expected {quoted} (they describe the hand and the object: no default, '
            "e.g. in the '/**' section), got none"
        )
    schema = NODE_SCHEMAS.get(node_name, ())
    missing = [spec.name for spec in schema if spec.required and spec.name not in values]
    if not missing:
        return
    quoted = ', '.join(f"'{name}'" for name in missing)
    got = (
        f"the file has no '{node_name}' section"
        if has_own_section is False
        else 'no parameter file section or -p rule gives them'
    )
    raise ParameterError(
        f'{source}: expected {quoted} in a {node_name!r} section (the initial grasp depends '
        f'on the hand: no default), got none: {got}'
    )
