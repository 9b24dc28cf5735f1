"""A controller node's per-tick kernels, loaded at start-up: one tick of spare cores.

numba loads a cached kernel at its first call, some 10 to 30 ms each: a controller node's
first tick would load those of its whole path (model terms, the filter's pass, margins;
the nominal law's), about 0.1 s of CPU, while a lockstep simulator and the filter's input
watchdog wait. Before it subscribes, a node runs its cores once on a spare model built from
the same parameters, at a made-up state (:func:`made_up_messages`) parsed as its inputs
are, so the arrays have the types the kernels are compiled for. The spare filter then runs
the steps of its rarer ticks on that tick's rows (:meth:`SafetyFilter.load_kernels
<grasp_safety_filter.control.safety_filter.SafetyFilter.load_kernels>`), which the first
relaxed tick would load otherwise.

The node's own model is not used: a model binds each contact to its object surface at its
first state (:meth:`~grasp_safety_filter.model.grasp_model.GraspModel.bind_contacts`), which
must be the hand's. Nor are the endpoints: they tick only on a state that passes the grasp
check, which a made-up state does not. A made-up state that a model or filter refuses ends
the warm-up early and quietly: the first tick then loads what is left, as before.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import Pose
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.control.startup_advice import rest_state, startup_advice
from grasp_safety_filter.io.messages import (
    effort_from_msg,
    effort_to_msg,
    joint_state_from_msg,
    joint_state_to_msg,
    MessageNamespace,
    ObjectStateData,
    odometry_from_msg,
    odometry_to_msg,
)
from grasp_safety_filter.model.compiled import load_compiled_runtime
from grasp_safety_filter.model.grasp_check import hand_findings
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.tick_state import model_state

#: What a made-up state may be refused with (its errors are not the user's).
_REFUSALS = (ValueError, ArithmeticError, np.linalg.LinAlgError)


def made_up_messages(model: GraspModel, msgs: MessageNamespace) -> tuple[Any, Any, Any]:
    """Return a joint state, an odometry and a zero effort command for ``model``'s hand.

    The joints at rest in the middle of their ranges; the object at rest, its origin at the
    fingertips' mean, its axes along the palm's. Not a grasp: only the types matter.
    """
    q = 0.5 * (model.joint_lower_limits + model.joint_upper_limits)
    zeros = np.zeros_like(q)
    p_fingertip_in_palm, _, _ = model.hand.fingertip_placements(q)
    names = list(model.joint_names)
    return (
        joint_state_to_msg(msgs, 0.0, names, q, zeros, None),
        odometry_to_msg(
            msgs,
            0.0,
            p_fingertip_in_palm.mean(axis=0),
            np.eye(3),
            np.zeros(6),
            model.palm_frame,
            model.object_frame,
        ),
        effort_to_msg(msgs, 0.0, names, zeros),
    )


def _made_up_tick(
    model: GraspModel, msgs: MessageNamespace
) -> tuple[GraspState, ObjectStateData, np.ndarray]:
    """Parse :func:`made_up_messages` and check the state as the endpoints do.

    Returns:
        The state, the odometry and the effort command (N·m).
    """
    joint_states_msg, odometry_msg, effort_msg = made_up_messages(model, msgs)
    names = tuple(model.joint_names)
    joints = joint_state_from_msg(joint_states_msg, names)
    odometry = odometry_from_msg(odometry_msg, model.palm_frame, model.object_frame)
    state = model_state(model, joints, odometry)
    # The start-up grasp check evaluates the contacts' geometry, then the hand at the
    # state's own read-only arrays (another specialisation of the model's kernel); a
    # made-up state never gets that far in grasp_findings, so both are called directly.
    model.contact_geometry(state.q, state.p_object_in_palm, state.R_object_to_palm)
    hand_findings(model, state.q, state.p_object_in_palm, state.R_object_to_palm)
    return state, odometry, effort_from_msg(effort_msg, names).effort


def _spare_tick(
    parameters: Mapping[str, Any],
    config_directory: Path,
    msgs: MessageNamespace,
    tick: Callable[[GraspModel, GraspState, ObjectStateData, np.ndarray], object],
) -> bool:
    """Run ``tick`` once on a spare model at the made-up state; False if refused."""
    load_compiled_runtime()
    try:
        with np.errstate(all='ignore'):
            spare = GraspModel.from_parameters(parameters, config_directory)
            tick(spare, *_made_up_tick(spare, msgs))
    except _REFUSALS:
        return False
    return True


def load_filter_kernels(
    parameters: Mapping[str, Any],
    config_directory: Path,
    config: SafetyFilterConfig,
    msgs: MessageNamespace,
) -> bool:
    """Tick a spare filter on a spare model once, margins included; False if refused.

    Args:
        parameters: The node's validated parameters (its model's are read).
        config_directory: Where the parameter file's relative paths start.
        config: The node's filter configuration.
        msgs: The node's message classes.

    """

    def tick(spare: GraspModel, state: GraspState, _: ObjectStateData, u_nom: np.ndarray) -> None:
        safety_filter = SafetyFilter.from_config(spare, config)
        result = safety_filter.solve(state, u_nom)
        result.margins  # noqa: B018 (read on the ticks that publish them: loads their kernels)
        safety_filter.margins(state, u_nom)  # a filter switched off publishes these
        safety_filter.load_kernels()  # those of the rarer ticks, on this tick's rows
        # The start-up advice at the first tick (its rows at rest, HiGHS): ~10 ms the first
        # time in a process, which would stall the input streams then.
        startup_advice(safety_filter, rest_state(spare, state))

    return _spare_tick(parameters, config_directory, msgs, tick)


def load_nominal_kernels(
    parameters: Mapping[str, Any],
    config_directory: Path,
    config: NominalConfig,
    msgs: MessageNamespace,
) -> bool:
    """Run a spare nominal controller on a spare model once; False if refused (see above)."""

    def tick(_: GraspModel, state: GraspState, odometry: ObjectStateData, __: np.ndarray) -> None:
        pose = Pose(odometry.p_object_in_palm, odometry.R_object_to_palm)
        sample = config.make_reference(pose, state.t).sample(state.t)
        NominalController(config).compute(state, sample)
        sample.twist  # noqa: B018 (published with each tick's sample: loads its kernel)

    return _spare_tick(parameters, config_directory, msgs, tick)
