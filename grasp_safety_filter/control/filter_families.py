"""The safety filter's barrier families: built from its configuration, the enabled ones chosen."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np

from grasp_safety_filter.control.constraints import (
    ConstraintFamily,
    FingertipWorkspaceBarrier,
    FrictionPyramid,
    JointLimitBarrier,
    ObjectWorkspaceBarrier,
    TorqueRateBound,
)
from grasp_safety_filter.control.filter_config import SafetyFilterConfig
from grasp_safety_filter.model.grasp_state import GraspState

#: Writes a family's rows at a state into rows ``start:`` of the stacked ``A`` and ``lower``:
#: ``write(state, A, lower, start)``.
RowWriter = Callable[[GraspState, np.ndarray, np.ndarray, int], None]


def enabled_families(
    config: SafetyFilterConfig,
    joint_names: tuple[str, ...],
    contact_names: Sequence[str],
    q_min: Sequence[float] | np.ndarray,
    q_max: Sequence[float] | np.ndarray,
    mu: float | Sequence[float] | np.ndarray,
    workspace: tuple[float, float, float, float],
    object_workspace: ObjectWorkspaceBarrier | None,
    torsional_friction: float | Sequence[float] | np.ndarray | None = None,
) -> tuple[list[tuple[ConstraintFamily, float]], tuple[str, ...], TorqueRateBound | None]:
    """Build every family, validating its arguments, and keep the enabled ones.

    The arguments are :class:`~grasp_safety_filter.control.safety_filter.SafetyFilter`'s
    (``joint_names`` already validated by its actuator limits); ``torsional_friction`` is
    the soft fingers' mu_t (None: point contacts), for the no-slip rows.

    Returns:
        The enabled families with their slack weights, in row order (no slip, joint
        limits, fingertip workspace, object workspace, torque rate); the validated contact
        names; the torque-rate family (None unless ``torque_rate.enabled``).

    Raises:
        ValueError: A malformed argument; the message names it.
    """
    # Validated by every family that uses them; built here so that a bad argument is
    # reported even when its family is switched off.
    no_slip = FrictionPyramid(
        contact_names,
        mu,
        config.pyramid_faces,
        config.normal_force_margin,
        config.friction_margin,
        config.cone,
        torsional_friction,
    )
    contacts = no_slip.contact_names
    joint_limits = JointLimitBarrier(joint_names, q_min, q_max, config.alpha1, config.alpha2)
    try:
        a_min, a_max, b_min, b_max = workspace
    except (TypeError, ValueError):
        raise ValueError(
            f"'workspace': expected (a_min, a_max, b_min, b_max), got {workspace!r}"
        ) from None
    fingertip_workspace = FingertipWorkspaceBarrier(
        contacts, a_min, a_max, b_min, b_max, config.alpha1, config.alpha2
    )
    chosen: list[tuple[ConstraintFamily, float]] = []
    if config.no_slip_enabled:
        chosen.append((no_slip, config.no_slip_weight))
    if config.joint_limits_enabled:
        chosen.append((joint_limits, config.joint_limits_weight))
    if config.fingertip_workspace_enabled:
        chosen.append((fingertip_workspace, config.fingertip_workspace_weight))
    if config.object_workspace_enabled:
        if not isinstance(object_workspace, ObjectWorkspaceBarrier) or (
            object_workspace.contact_names != contacts
        ):
            raise ValueError(
                "'object_workspace': expected an ObjectWorkspaceBarrier of the contacts "
                f'{list(contacts)} with object_workspace.enabled, got '
                f'{object_workspace!r}'
            )
        chosen.append((object_workspace, config.object_workspace_weight))
    torque_rate: TorqueRateBound | None = None
    if config.torque_rate_enabled:
        torque_rate = TorqueRateBound(
            joint_names, config.torque_rate_max_step, config.torque_rate_max_rate
        )
        chosen.append((torque_rate, config.torque_rate_weight))
    return chosen, contacts, torque_rate


def object_workspace_of(
    grasp_model: Any, config: SafetyFilterConfig
) -> ObjectWorkspaceBarrier | None:
    """Return a ``GraspModel``'s object-workspace family, None unless enabled in ``config``.

    Its contacts' object surfaces (:meth:`ObjectWorkspaceBarrier.for_model`).
    """
    if not config.object_workspace_enabled:
        return None
    return ObjectWorkspaceBarrier.for_model(
        grasp_model,
        config.object_workspace_margin,
        (
            config.object_workspace_sphere_a_half_width,
            config.object_workspace_sphere_b_half_width,
        ),
        config.alpha1,
        config.alpha2,
    )


def row_writers(families: Sequence[ConstraintFamily]) -> tuple[RowWriter, ...]:
    """Per family, its rows' writer (:data:`RowWriter`).

    ``rows_into`` where the family has one (no array per tick), else its ``rows()`` copied in.
    """
    return tuple(
        family.rows_into if hasattr(family, 'rows_into') else partial(_copy_rows, family)
        for family in families
    )


def rows_compiled(families: Sequence[ConstraintFamily]) -> bool:
    """Whether every family's writer runs compiled code only on a packed state.

    No numpy floating-point warning can then come from writing the rows, and the filter
    does not enter ``np.errstate`` (a few µs a tick).
    """
    return all(getattr(family, 'compiled_packed_rows', False) for family in families)


def _copy_rows(
    family: ConstraintFamily, state: GraspState, A: np.ndarray, lower: np.ndarray, start: int
) -> None:
    """Copy a family's rows at ``state`` into rows ``start:`` of the stacked A and lower."""
    block = family.rows(state)
    rows = slice(start, start + len(family.names))
    A[rows] = block.A
    lower[rows] = block.lower
