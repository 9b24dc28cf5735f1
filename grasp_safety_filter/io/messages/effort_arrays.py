"""``std_msgs/Float64MultiArray``: joint torques in ros2_control's form.

An ``effort_controllers/JointGroupEffortController`` takes its command on
``<controller>/commands`` as a ``Float64MultiArray`` whose ``data`` holds one torque per
joint of its ``joints`` parameter, in that order, with no names and no stamp (the layout is
left empty, as ``ros2 topic pub`` sends it). The order is configured once, by name, and
turned into an index here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import MessageError, name_list
from grasp_safety_filter.io.messages.fields import array_field, checked_names
from grasp_safety_filter.io.messages.namespace import MessageNamespace


def joint_order(
    source: str, array_joints: Sequence[str], model_joints: Sequence[str]
) -> np.ndarray:
    """Return the index of each array entry's joint in the model's joint order.

    ``array[i] = model_vector[index[i]]``: ``array_joints`` (the controller's ``joints``)
    must name every model joint exactly once, and nothing else.

    Raises:
        MessageError: Duplicate, unknown or missing joints, naming them and ``source``.

    """
    array_joints = checked_names(source, array_joints, 'joint')
    index = {name: i for i, name in enumerate(model_joints)}
    unknown = [name for name in array_joints if name not in index]
    missing = [name for name in model_joints if name not in set(array_joints)]
    if unknown or missing:
        raise MessageError(
            f"{source}: expected each of the model's {len(index)} joints exactly once; "
            f'not model joints: {name_list(unknown)}, model joints missing: {name_list(missing)}'
        )
    return np.array([index[name] for name in array_joints], dtype=int)


def effort_array_to_msg(msgs: MessageNamespace, order: np.ndarray, effort: np.ndarray) -> Any:
    """Build a ``Float64MultiArray`` of ``effort`` (model order, N·m) in the array's order."""
    data = msgs.float_array(np.asarray(effort, dtype=float)[order])
    return msgs.Float64MultiArray(layout=msgs.MultiArrayLayout(dim=[], data_offset=0), data=data)


def effort_array_from_msg(msg: Any, order: np.ndarray, source: str) -> np.ndarray:
    """Return the torques of a ``Float64MultiArray`` in model joint order, N·m.

    Args:
        msg: The message; ``data`` has one entry per joint of the array's order.
        order: :func:`joint_order` of that order.
        source: Name used in error messages (the topic).

    Raises:
        MessageError: Another number of entries, or a non-finite entry.

    """
    names = [str(i) for i in range(len(order))]
    data = array_field(source, msg.data, 'data', names, required=True)
    effort = np.empty(len(order))
    effort[order] = data
    return effort
