"""Parameters that have no meaningful default: a node refuses to start unless they are given.

The initial grasp of ``hand_sim_node`` (``initial.joint_positions``,
``initial.object_position``) is the hand's own: the schema's defaults are the paper's hand's
and mean nothing on another one, so a scenario file without them (no ``hand_sim_node``
section, or a section that leaves them out) is refused, by the ROS-free loader and by the
node, with a message naming the section.

Every other parameter keeps its documented default when no file section gives it: the
nominal controller's gains and the safety filter's settings are the paper's and do not
depend on the hand's geometry, and a filter run on a real hand with only the shared
``/**`` section (README, "The filter on your own hand") is the intended use. The model's
``model.*`` defaults describe the paper's hand (``model.urdf_file`` its URDF).
"""

from __future__ import annotations

from collections.abc import Iterable

from grasp_safety_filter.io.parameters import ParameterError

#: Per node, the parameters that must be given (by a file section or on the command line).
REQUIRED_PARAMETERS: dict[str, tuple[str, ...]] = {
    'hand_sim_node': ('initial.joint_positions', 'initial.object_position'),
}


def check_required_parameters(
    node_name: str, given: Iterable[str], source: str, has_own_section: bool | None = None
) -> None:
    """Raise ParameterError unless every parameter of :data:`REQUIRED_PARAMETERS` is given.

    Args:
        node_name: The node's schema name, e.g. ``"hand_sim_node"``.
        given: The names the files and the command line give the node.
        source: Where they come from (file and node), prefixed to the message.
        has_own_section: Whether a file has a section for this very node (None: unknown).
    """
    names = set(given)
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
