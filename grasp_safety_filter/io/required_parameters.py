"""Parameters that have no meaningful default: a node refuses to start unless they are given.

The initial grasp of ``hand_sim_node`` (``initial.joint_positions``,
``initial.object_position``) is the hand's own: the schema's defaults are the paper's hand's
and mean nothing on another one, so a scenario file without them (no ``hand_sim_node``
section, or a section that leaves them out) is refused, by the ROS-free loader and by the
node, with a message naming the section.

Every other parameter keeps its documented default when no file section gives it: the
nominal controller's gains and the safety filter's settings are the paper's and do not
depend on the hand's geometry, and a filter run on a real hand with only the shared
``/**`` section (README, "Using your own hand") is the intended use.

The ``model.*`` parameters that describe the hand and the object
(:data:`grasp_safety_filter.io.schemas.REQUIRED_MODEL_PARAMETERS`, and the object's
dimensions for its shape) are required by every node: their schema defaults are the paper's
hand's, which would silently describe a different hand (a 6 cm fingertip on a 12 mm one).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from grasp_safety_filter.io.parameters import ParameterError

#: Per node, the parameters that must be given (by a file section or on the command line).
REQUIRED_PARAMETERS: dict[str, tuple[str, ...]] = {
    'hand_sim_node': ('initial.joint_positions', 'initial.object_position'),
}


def check_required_parameters(
    node_name: str,
    given: Mapping[str, Any] | Iterable[str],
    source: str,
    has_own_section: bool | None = None,
) -> None:
    """Raise ParameterError unless every required parameter is given.

    The model's (:func:`~grasp_safety_filter.io.schemas.required_model_parameters`) first,
    then the node's own (:data:`REQUIRED_PARAMETERS`).

    Args:
        node_name: The node's schema name, e.g. ``"hand_sim_node"``.
        given: The parameters (name: value, or names) the files and the command line give
            the node.
        source: Where they come from (file and node), prefixed to the message.
        has_own_section: Whether a file has a section for this very node (None: unknown).
    """
    from grasp_safety_filter.io.schemas import required_model_parameters

    values = given if isinstance(given, Mapping) else dict.fromkeys(given)
    names = set(values)
    missing_model = [name for name in required_model_parameters(values) if name not in names]
    if missing_model:
        quoted = ', '.join(f"'{name}'" for name in missing_model)
        raise ParameterError(
            f'{source}: expected {quoted} (they describe the hand and the object: no default, '
            "e.g. in the '/**' section), got none"
        )
    missing = [name for name in REQUIRED_PARAMETERS.get(node_name, ()) if name not in names]
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
