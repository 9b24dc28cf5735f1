"""The tick's rows: the enabled constraint families stacked as ``A u >= lower``, and its inputs.

:class:`FilterRows` builds every family from the filter's arguments and keeps the enabled
ones in row order (no slip, joint limits, fingertip workspace, object workspace, torque
rate); each tick each writes its block of the stacked ``A`` (K, m) and ``lower`` (K,) in
place. Before any solver call the tick's inputs are checked: u_nom (:func:`checked_torque`)
and, under rows that are not finite, the measured state (:func:`raise_if_measured_not_finite`).

The checks on the stacked rows are compiled loops (:mod:`grasp_safety_filter.model.compiled`)
over at most a few dozen rows of m ≤ 16 torques, where the numpy expressions they replace
(``np.isfinite(x).all()``, ``(A @ u >= lower).all()``) cost a microsecond or two of call
overhead each.
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import nullcontext
import itertools
import math
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
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.grasp_state import GraspState

#: The measured :class:`GraspState` fields (the arguments of ``GraspModel.state``); every
#: other field is a model term derived from them.
MEASURED_STATE_FIELDS: tuple[str, ...] = (
    'q',
    'dq',
    'p_object_in_palm',
    'R_object_to_palm',
    'twist_object',
)

_NO_VALUES = np.zeros(0)
_NO_CONTEXT = nullcontext()


class FilterRows:
    """The enabled barrier families and their blocks in the stacked rows ``A u >= lower``.

    Attributes:
        families: The enabled families, in row order.
        weights: Each enabled family's slack weight (relaxed problem), in the same order.
        contact_names: The validated contact names.
        torque_rate: The torque-rate family (None unless ``torque_rate.enabled``).
        names: The rows' names, in row order.
        slices: Each family's block of rows.
    """

    def __init__(
        self,
        config: SafetyFilterConfig,
        joint_names: tuple[str, ...],
        contact_names: Sequence[str],
        q_min: Sequence[float] | np.ndarray,
        q_max: Sequence[float] | np.ndarray,
        mu: float | Sequence[float] | np.ndarray,
        workspace: tuple[float, float, float, float],
        object_workspace: ObjectWorkspaceBarrier | None,
        torsional_friction: float | Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """Build every family, validating its arguments, and keep the enabled ones.

        The arguments are :class:`~grasp_safety_filter.control.safety_filter.SafetyFilter`'s
        (``joint_names`` already validated by its actuator limits).

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
        joint_limits = JointLimitBarrier(
            joint_names,
            *_inset(q_min, q_max, config.joint_limits_margin, 'joint_limits.margin'),
            config.alpha1,
            config.alpha2,
        )
        try:
            a_min, a_max, b_min, b_max = workspace
        except (TypeError, ValueError):
            raise ValueError(
                f"'workspace': expected (a_min, a_max, b_min, b_max), got {workspace!r}"
            ) from None
        margin = config.fingertip_workspace_margin
        fingertip_workspace = FingertipWorkspaceBarrier(
            contacts,
            *_inset(a_min, a_max, margin, 'fingertip_workspace.margin'),
            *_inset(b_min, b_max, margin, 'fingertip_workspace.margin'),
            config.alpha1,
            config.alpha2,
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
        self.torque_rate: TorqueRateBound | None = None
        if config.torque_rate_enabled:
            self.torque_rate = TorqueRateBound(
                joint_names, config.torque_rate_max_step, config.torque_rate_max_rate
            )
            chosen.append((self.torque_rate, config.torque_rate_weight))
        self.contact_names = contacts
        self.families: tuple[ConstraintFamily, ...] = tuple(f for f, _ in chosen)
        self.weights: tuple[float, ...] = tuple(w for _, w in chosen)
        self.names: tuple[str, ...] = tuple(n for f in self.families for n in f.names)
        sizes = [len(family.names) for family in self.families]
        ends = list(itertools.accumulate(sizes))
        self.slices = [slice(end - size, end) for size, end in zip(sizes, ends, strict=True)]
        self._n_joints = len(joint_names)
        self._writers = tuple(
            (family.rows_into, rows.start)
            for family, rows in zip(self.families, self.slices, strict=True)
        )
        # Compiled writers on a packed state raise no numpy warning: no np.errstate (µs).
        self._compiled = all(family.compiled_packed_rows for family in self.families)

    def write(self, state: GraspState, A: np.ndarray, lower: np.ndarray) -> None:
        """Write every family's rows at ``state`` into its block of ``A`` (K, m) and ``lower``.

        Raises:
            ValueError: The state has the wrong number of joints or contacts, or a field a
                family reads has the wrong shape.
        """
        if state.n_joints != self._n_joints or state.n_contacts != len(self.contact_names):
            raise ValueError(
                f'state: expected {self._n_joints} joints and {len(self.contact_names)} '
                f'contacts, got {state.n_joints} and {state.n_contacts}'
            )
        quiet = self._compiled and getattr(state, 'packed_terms', None) is not None
        with _NO_CONTEXT if quiet else np.errstate(all='ignore'):
            for write, start in self._writers:
                write(state, A, lower, start)


def _inset(lower: Any, upper: Any, margin: float, parameter: str) -> tuple[Any, Any]:
    """Return the bounds ``(lower + margin, upper - margin)`` (as given when the margin is 0).

    Raises:
        ValueError: The margin leaves no room between two bounds (naming ``parameter``).
    """
    if margin == 0.0:
        return lower, upper
    try:
        lower, upper = np.broadcast_arrays(np.asarray(lower, float), np.asarray(upper, float))
    except (TypeError, ValueError):
        return lower, upper  # malformed: the family names it
    crossed = np.flatnonzero(np.atleast_1d(upper - lower <= 2.0 * margin))
    if crossed.size:
        k = int(crossed[0])
        raise ValueError(
            f"'{parameter}': {margin} leaves no room between the bounds "
            f'{float(np.atleast_1d(lower)[k])} and {float(np.atleast_1d(upper)[k])}: expected '
            'less than half of every range'
        )
    return lower + margin, upper - margin


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


def checked_torque(u_nom: object, joint_names: Sequence[str]) -> np.ndarray:
    """Return u_nom as a new float array of shape (m,), finite.

    Raises:
        ValueError: Not numbers, the wrong shape or a non-finite entry (naming its joint).
    """
    m = len(joint_names)
    try:
        u = np.array(u_nom, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'u_nom: expected {m} numbers, got {u_nom!r}') from None
    if u.shape != (m,):
        raise ValueError(f'u_nom: expected shape ({m},), got {u.shape}')
    if not all_finite(u, _NO_VALUES):  # compiled: np.isfinite(u).all() costs ~2 µs a tick
        bad = np.flatnonzero(~np.isfinite(u))
        raise ValueError(f'u_nom: non-finite value {u[bad[0]]} for joint {joint_names[bad[0]]!r}')
    return u


def raise_if_measured_not_finite(state: GraspState) -> None:
    """Raise ValueError naming the first non-finite entry of a measured field, if any."""
    for name in MEASURED_STATE_FIELDS:
        value = getattr(state, name)
        arrays = (
            ((f'{name}.matrix', value.matrix), (f'{name}.offset', value.offset))
            if isinstance(value, AffineMap)
            else ((name, value),)
        )
        for label, array in arrays:
            bad = np.argwhere(~np.isfinite(np.asarray(array, dtype=float)))
            if bad.size:
                index = tuple(int(i) for i in bad[0])
                raise ValueError(
                    f'state.{label}: non-finite value {array[index]} at index '
                    f'{index[0] if len(index) == 1 else index}'
                )


@kernel
def row_dot(A: np.ndarray, r: int, u: np.ndarray) -> float:
    """``A[r] · u``, summed from the first column on (every row check sums the same way)."""
    total = 0.0
    for c in range(u.shape[0]):
        total += A[r, c] * u[c]
    return total


@kernel
def all_finite(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether every entry of both 1-D arrays is finite (neither inf nor NaN)."""
    for value in first:
        if not math.isfinite(value):
            return False
    for value in second:
        if not math.isfinite(value):
            return False
    return True


@kernel
def inside(
    A: np.ndarray, lower: np.ndarray, u: np.ndarray, u_min: np.ndarray, u_max: np.ndarray
) -> bool:
    """Whether u satisfies every row ``A u >= lower`` and the box ``u_min <= u <= u_max``.

    A NaN anywhere counts as not satisfied.
    """
    for r in range(A.shape[0]):
        if not row_dot(A, r, u) >= lower[r]:
            return False
    for j in range(u.shape[0]):
        if not (u[j] >= u_min[j] and u[j] <= u_max[j]):
            return False
    return True
