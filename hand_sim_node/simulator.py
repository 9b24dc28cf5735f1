"""The hand–object plant: constrained rolling-contact dynamics under a held joint torque.

State ``x = (q, dq, p_o, quat_o, x_o_dot)``: joint angles and rates, the object's centre of
mass and orientation (unit quaternion ``(x, y, z, w)`` of ``R_object_to_palm``) in the palm
frame, and the object twist ``(v_o, w_o)`` in palm coordinates. Its rate is

    q_dot = dq,        dq_dot = M_h^-1 (u - h_bias - J_h^T f_c)
    p_o_dot = v_o,     quat_o_dot = 1/2 (0, w_o) ⊗ quat_o
    x_o_ddot = M_o^-1 (G f_c + w_e - C_o x_o_dot)

with the contact forces of the rolling constraint ``J_h dq = G^T x_o_dot`` plus a
Baumgarte correction that pulls the constraint back when integration error lets it drift.
With the contact velocity residual ``e = J_h dq - G^T x_o_dot`` (per contact, contact frame:
fingertip material velocity minus object material velocity at the contact point) and the
normal interpenetration ``δ_i`` (``δ_i_dot = e_n,i``),

    e_dot = J_h ddq + J_h_dot dq - G^T x_o_ddot - G_dot^T x_o_dot = B_ho (f_c(u) - f_c)

where ``f_c(u)`` is the model's affine contact force (the one that makes ``e_dot = 0``).
Choosing

    f_c = f_c(u) + B_ho^-1 (K_v e + K_p [0, 0, δ_i]_i)

gives ``e_dot = -K_v e - K_p [0, 0, δ_i]``: on the normal ``δ_ddot + K_v δ_dot + K_p δ = 0``
(the gap decays), tangentially the slip velocity decays at rate ``K_v``. On the exact
solution ``e = 0, δ = 0`` and the correction vanishes, so it does no work there.

The contact coordinates, frames and model terms are recomputed from the configuration at
every Runge–Kutta stage. The first stage reads the :class:`GraspState` the controller
reads (computed once per state, or handed to :meth:`Simulator.step` by an in-process loop
that has built it already); the other stages evaluate only the terms the rate needs
(:mod:`hand_sim_node.stage`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import (
    normalized,
    rotation_matrix,
)
from hand_sim_node.config import SimConfig
from hand_sim_node.constraint_margins import (
    ConstraintMargins,
    Event,
    FINGERTIP_WORKSPACE,
    SLIP,
)
from hand_sim_node.events import EventMonitor
from hand_sim_node.integrators import integrator
from hand_sim_node.run_record import RunRecord
from hand_sim_node.stage import PlantRate

NUMERICAL_FAILURE = 'numerical_failure'
"""Stop reason when the dynamics cannot be evaluated (singular B_ho or M_h, non-finite state)."""


@dataclass(frozen=True, eq=False)
class SimState:
    """The plant's state at one instant (read-only arrays).

    Attributes:
        t: Time, s.
        q: Joint angles, shape (m,), rad.
        dq: Joint velocities, shape (m,), rad/s.
        p_object_in_palm: Object centre of mass, shape (3,), m.
        quaternion_object: Unit quaternion ``(x, y, z, w)`` of ``R_object_to_palm``, (4,).
        twist_object: Object twist ``(v_o, w_o)``, palm coordinates, shape (6,), (m/s, rad/s).

    """

    t: float
    q: np.ndarray
    dq: np.ndarray
    p_object_in_palm: np.ndarray
    quaternion_object: np.ndarray
    twist_object: np.ndarray

    def __post_init__(self) -> None:
        for name in ('q', 'dq', 'p_object_in_palm', 'quaternion_object', 'twist_object'):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, 't', float(self.t))

    @cached_property
    def R_object_to_palm(self) -> np.ndarray:
        """Object orientation as a rotation matrix, shape (3, 3) (computed once, read-only)."""
        R = rotation_matrix(self.quaternion_object)
        R.setflags(write=False)
        return R

    def to_vector(self) -> np.ndarray:
        """Flat state ``(q, dq, p_o, quat_o, x_o_dot)``, shape (2m + 13,)."""
        return np.concatenate(
            (self.q, self.dq, self.p_object_in_palm, self.quaternion_object, self.twist_object)
        )

    @classmethod
    def from_vector(cls, t: float, x: np.ndarray, n_joints: int) -> SimState:
        """Inverse of :meth:`to_vector` for a hand with ``n_joints`` joints."""
        m = n_joints
        return cls(
            t,
            x[:m],
            x[m : 2 * m],
            x[2 * m : 2 * m + 3],
            x[2 * m + 3 : 2 * m + 7],
            x[2 * m + 7 : 2 * m + 13],
        )


@dataclass(frozen=True, eq=False)
class StepReport:
    """What happened over one step.

    Everything but ``state`` is evaluated at the start of the step (``start.t``), the
    instant the torque was computed for, so one report is one consistent sample.

    Attributes:
        start: State at the start of the step.
        state: State at the end of the step (``start`` if the run stopped at this step).
        grasp_state: Model terms at ``start``; None if the model refused that state (a
            singular ``B_ho`` or terms that are not finite: ``"numerical_failure"``).
        effort: Joint torque applied over the step, shape (m,), N·m.
        contact_force: Contact forces at ``start`` under ``effort`` (with the constraint
            stabilisation), shape (k,) (3n, or 4n with soft fingers), contact frames, N (N·m).
        margins: Every constraint margin at ``start``.
        events: The constraints violated at ``start``.
        stop_reason: None, or why the run stopped at this step (``"fingertip_workspace"``,
            ``"slip"``, ``"numerical_failure"``); the step was then not integrated.

    """

    start: SimState
    state: SimState
    grasp_state: GraspState | None
    effort: np.ndarray
    contact_force: np.ndarray
    margins: ConstraintMargins
    events: tuple[Event, ...]
    stop_reason: str | None


def contact_velocity_residual(state: GraspState) -> np.ndarray:
    """Rolling-constraint residual ``e = J_h dq - G^T x_o_dot``, shape (k,), m/s.

    With soft fingers (k = 4n) the last n entries are spin residuals, rad/s.

    Per contact, in its contact frame: velocity of the fingertip's material point at the
    contact minus the object's; zero under pure rolling, ``e_n,i`` is the rate of
    interpenetration.
    """
    return state.J_h @ state.dq - state.G.T @ state.twist_object


def initial_state(model: Any, config: SimConfig) -> SimState:
    """Return the configured initial grasp at rest, the joints projected onto exact contact.

    The state :meth:`Simulator.reset` and the plants start from.
    """
    R_object_to_palm = rotation_matrix(config.initial_object_orientation)
    q = model.project_to_contact(
        config.initial_joint_positions, config.initial_object_position, R_object_to_palm
    )
    return SimState(
        0.0,
        q,
        np.zeros(model.n_joints),
        config.initial_object_position,
        config.initial_object_orientation,
        np.zeros(6),
    )


class Simulator(RunRecord):
    """Fixed-step simulator of the grasp model under a joint torque held over each step.

    Args:
        model: A ``GraspModel`` (``state``, ``project_to_contact``, ``n_joints``,
            limits, workspace, friction coefficient and names).
        config: Initial state, integrator, step, stabilisation gains, stop rules.

    Raises:
        ValueError: ``config.initial_joint_positions`` does not have one angle per joint.

    """

    def __init__(self, model: Any, config: SimConfig) -> None:
        if config.initial_joint_positions.shape != (model.n_joints,):
            raise ValueError(
                f"parameter 'initial.joint_positions': expected {model.n_joints} joint angles "
                f'({", ".join(model.joint_names)}), got {config.initial_joint_positions.size}'
            )
        self.model = model
        self.config = config
        self.monitor = EventMonitor.from_model(model)
        self._tableau = integrator(config.integrator)
        self._rate = PlantRate(model)
        self._m = model.n_joints
        self.reset()

    # ----------------------------------------------------------------------------- state
    def reset(self, state: SimState | None = None) -> SimState:
        """Restart the run (time, step count, event log) from ``state``.

        Without ``state``: the configured initial pose, joint angles projected onto the
        contact manifold (every fingertip touching its face exactly), at rest.
        """
        if state is None:
            state = initial_state(self.model, self.config)
        self._restart(state)
        return state

    @property
    def state(self) -> SimState:
        """The current state."""
        return self._state

    @property
    def t(self) -> float:
        """The current time, s."""
        return self._state.t

    # -------------------------------------------------------------------------- dynamics
    def derivative(
        self, state: GraspState, effort: np.ndarray, quaternion_xyzw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """State rate at ``state`` under ``effort``, and the contact forces used.

        Args:
            state: Model terms at the state.
            effort: Joint torque u, shape (m,), N·m.
            quaternion_xyzw: The state's orientation quaternion as integrated (possibly
                not unit inside a Runge–Kutta step).

        Returns:
            ``x_dot`` with the layout of :meth:`SimState.to_vector`, and ``f_c`` (k,): 3n, or
            4n with soft fingers.

        """
        config = self.config
        return self._rate.from_state(
            state, effort, quaternion_xyzw, config.position_gain, config.velocity_gain
        )

    # ------------------------------------------------------------------------------ step
    def step(self, effort: np.ndarray, state: GraspState | None = None) -> StepReport:
        """Integrate one ``time_step`` with the joint torque ``effort`` held constant.

        The constraint families are evaluated at the start of the step (the instant the
        torque was computed for) and recorded in :attr:`log`. If a stopping event occurs
        (workspace exit with ``stop_on_workspace_exit``, slip with ``stop_on_slip``) or the
        dynamics cannot be evaluated, the step is not integrated and :attr:`stop_reason`
        is set.

        Args:
            effort: Joint torque u in the model's joint order, shape (m,), N·m.
            state: The model terms of the current state if the caller has built them
                already (``model.state(s.t, s.q, s.dq, s.p_object_in_palm,
                s.R_object_to_palm, s.twist_object)`` of ``s = simulator.state``, with this
                simulator's model): used as the first Runge–Kutta stage instead of a new
                evaluation. Its time, joint angles and rates, object pose and twist must
                equal the simulator's own exactly.

        Raises:
            RuntimeError: The run has already stopped (call :meth:`reset`).
            ValueError: ``effort`` has the wrong shape or is not finite, or ``state`` is
                not the current state.

        """
        u = self._checked_effort(effort)
        if state is not None and state is not self._grasp_state:
            self._check_current(state)
            self._grasp_state = state
        start = self._state
        x0 = start.to_vector()
        m = self._m
        quaternion = slice(2 * m + 3, 2 * m + 7)
        k1, f_c = None, np.full(self.model.wrench_size, np.nan)
        try:
            state0: GraspState | None = self.grasp_state()
        except np.linalg.LinAlgError:
            state0 = None  # not finite or B_ho singular: judged on the configuration alone
            unknown = np.full((self.model.n_contacts, 2), np.nan)
            margins = self.monitor.margins_at(start.t, start.q, unknown, f_c)
        else:
            try:
                k1, f_c = self.derivative(state0, u, x0[quaternion])
            except np.linalg.LinAlgError:
                pass
            margins = self.monitor.margins(state0, f_c)
        events = self.monitor.events(margins)
        self.log.record(margins, events)

        stop_reason = self._stopping(events)
        if stop_reason is None and k1 is None:
            stop_reason = NUMERICAL_FAILURE
        if stop_reason is None:
            t0, dt = start.t, self.config.time_step
            gains = (self.config.position_gain, self.config.velocity_gain)

            def rate(_t: float, x: np.ndarray) -> np.ndarray:
                return self._rate.at(x, u, *gains)

            try:
                x1 = self._tableau.step(rate, t0, x0, dt, k1=k1)
                x1[quaternion] = normalized(x1[quaternion])
                finite = bool(np.all(np.isfinite(x1)))
            except (np.linalg.LinAlgError, ValueError):
                finite = False
            if finite:
                self._step_index += 1
                # t from the step count: no round-off accumulation over long runs.
                t1 = self._t0 + self._step_index * dt
                self._state = SimState.from_vector(t1, x1, m)
                self._grasp_state = None
            else:
                stop_reason = NUMERICAL_FAILURE
        self._stop_reason = stop_reason
        return StepReport(
            start=start,
            state=self._state,
            grasp_state=state0,
            effort=u,
            contact_force=f_c,
            margins=margins,
            events=events,
            stop_reason=stop_reason,
        )

    def _check_current(self, state: GraspState) -> None:
        """Refuse a grasp state that is not exactly the simulator's current state (ValueError)."""
        current = self._state
        mismatched = [
            name
            for name, theirs, ours in (
                ('t', np.float64(state.t), np.float64(current.t)),
                ('q', state.q, current.q),
                ('dq', state.dq, current.dq),
                ('p_object_in_palm', state.p_object_in_palm, current.p_object_in_palm),
                ('R_object_to_palm', state.R_object_to_palm, current.R_object_to_palm),
                ('twist_object', state.twist_object, current.twist_object),
            )
            if np.shape(theirs) != np.shape(ours) or not (theirs == ours).all()
        ]
        if mismatched:
            raise ValueError(
                f'Simulator.step: the given grasp state is not the current state (t = '
                f'{current.t} s): its {", ".join(mismatched)} differ; build it from '
                'simulator.state or pass none'
            )

    def _stopping(self, events: tuple[Event, ...]) -> str | None:
        families = {event.family for event in events}
        if self.config.stop_on_workspace_exit and FINGERTIP_WORKSPACE in families:
            return FINGERTIP_WORKSPACE
        if self.config.stop_on_slip and SLIP in families:
            return SLIP
        return None
