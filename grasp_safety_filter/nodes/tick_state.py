"""The model terms of a tick: ``GraspModel.state`` at a joint state and the object's state.

Both controllers, their start-up warm-up and the object's estimate at a joint state call
the model alike: the joint positions (rad) and velocities (rad/s) of a parsed joint state,
and the object's position (m), orientation and twist in the palm frame, from the odometry
or from the estimate at the joint state's stamp. :func:`timed_state` keeps the model's
refusal of a state (``ValueError``, ``np.linalg.LinAlgError``) as the tick's answer, with
the time the terms took (part of the tick's time, whenever computed).
"""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import JointStateData, MessageError
from grasp_safety_filter.model.grasp_state import GraspState

#: A state's model terms (or the model's refusal of it) and the time they took, s.
TimedState = tuple[GraspState | Exception, float]


def model_state(model: Any, joints: JointStateData, object_state: Any) -> GraspState:
    """Return the model terms at a joint state and the object's state at its stamp.

    Args:
        model: The ``GraspModel``.
        joints: The joint state, model joint order.
        object_state: Has ``p_object_in_palm`` (m), ``R_object_to_palm`` and
            ``twist_object`` (palm frame): the odometry or the object's estimate.

    Raises:
        ValueError: The model refuses the state (``np.linalg.LinAlgError`` too).

    """
    return model.state(
        joints.t,
        joints.position,
        joints.velocity,
        object_state.p_object_in_palm,
        object_state.R_object_to_palm,
        object_state.twist_object,
    )


def timed_state(compute: Callable[[], GraspState]) -> TimedState:
    """Return ``compute()`` (or the model's refusal of the state) and its duration, s.

    Raises:
        MessageError: An input refused on the way (not the model's refusal).

    """
    start = time.perf_counter()
    try:
        state: GraspState | Exception = compute()
    except MessageError:
        raise
    except (ValueError, np.linalg.LinAlgError) as error:
        state = error
    return state, time.perf_counter() - start
