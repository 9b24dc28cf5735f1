"""MuJoCo as a :class:`~hand_sim_node.plant.Plant`: soft contacts with Coulomb friction.

The MJCF is generated from our grasp model (:mod:`hand_sim_node.mjcf`). One control period
(the scenario's ``time_step``) is ``n_substeps`` MuJoCo steps with the torque held
(``ctrl``, clamped by MuJoCo to the URDF effort limits).

After each step the plant gives a :class:`~hand_sim_node.simulator.StepReport` as the rigid
simulator does: our model's terms at the start of the step, MuJoCo's contact forces on the
object over the step's first MuJoCo step (the forces of the start state under the applied
torque with the Euler and implicit integrators) in our contact frames, and the constraint
margins and events they give (:class:`~hand_sim_node.events.EventMonitor`, recorded in
:attr:`MuJoCoPlant.log`). The rigid model's stop rules (``stop_on_slip``,
``stop_on_workspace_exit``) do not apply: MuJoCo's contacts really slip and separate, and
the plant stops only when the object dropped or on a numerical failure.

Besides the state, the plant reports per contact what MuJoCo measures
(:class:`~hand_sim_node.plant.ContactReport`): whether the fingertip touches the object,
their distance, the normal and tangential contact force, the slip speed (relative
tangential velocity of the fingertip's and the object's material points at the contact)
and the slip distance accumulated since the reset; and whether the object dropped.

The ``mujoco`` package is imported here only, when the plant is built: without it the rest
of the package works, and asking for this plant raises :class:`MuJoCoUnavailableError`.
"""

from __future__ import annotations

from collections.abc import Iterator
from types import ModuleType
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from hand_sim_node.config import SimConfig
from hand_sim_node.events import EventMonitor
from hand_sim_node.mjcf import (
    fingertip_geom_name,
    mjcf_from_model,
    MjcfError,
    MjcfOptions,
    OBJECT_BODY,
)
from hand_sim_node.plant import ContactReport
from hand_sim_node.run_record import RunRecord
from hand_sim_node.simulator import initial_state, NUMERICAL_FAILURE, SimState, StepReport

__all__ = ['OBJECT_DROPPED', 'ContactReport', 'MuJoCoPlant', 'MuJoCoUnavailableError']

#: Stop reason when no fingertip touches the object any more, or it fell below the floor.
OBJECT_DROPPED = 'object_dropped'


class MuJoCoUnavailableError(ConfigError):
    """The MuJoCo plant was asked for and the ``mujoco`` package is not installed."""


def import_mujoco() -> ModuleType:
    """Return the ``mujoco`` module (MuJoCoUnavailableError naming the extra if missing)."""
    try:
        import mujoco
    except ImportError as error:
        raise MuJoCoUnavailableError(
            f"plant 'mujoco': the mujoco package is not installed ({error}); install the "
            "extra: pip install 'grasp_safety_filter[mujoco]' (or pip install 'mujoco>=3.2')"
        ) from None
    return mujoco


class MuJoCoPlant(RunRecord):
    """The grasp model's hand and object simulated by MuJoCo.

    Args:
        model: The grasp model (its URDF, fingertips, object and μ give the MJCF).
        config: The scenario's simulator configuration: the initial grasp and ``time_step``,
            the control period (its rigid-model settings do not apply).
        options: MuJoCo's contact and integration parameters (defaults: :class:`MjcfOptions`).
        touch_tolerance: A fingertip counts as touching up to this distance off the object,
            m (1 µm: round-off of an exact initial grasp, far below any real separation).
        min_object_height: The object dropped if its centre falls below this palm-frame
            height, m; None: only when no fingertip touches it.
        stop_on_drop: Whether a drop stops the run.
        distance_limit: Distances are measured up to this, m (farther reads as this).

    Raises:
        MuJoCoUnavailableError: No ``mujoco`` package.
        MjcfError: ``time_step`` is not a whole number of MuJoCo steps, or a bad option.
    """

    def __init__(
        self,
        model: GraspModel,
        config: SimConfig,
        options: MjcfOptions | None = None,
        *,
        touch_tolerance: float = 1e-6,
        min_object_height: float | None = None,
        stop_on_drop: bool = True,
        distance_limit: float = 1.0,
    ) -> None:
        self._mujoco = mujoco = import_mujoco()
        self.model = model
        self.config = config
        self.options = options = options or MjcfOptions()
        self.time_step = config.time_step
        n_substeps = round(config.time_step / options.timestep)
        if n_substeps < 1 or abs(n_substeps * options.timestep - config.time_step) > (
            1e-9 * config.time_step
        ):
            raise MjcfError(
                f'mujoco.timestep: expected the control period time_step = {config.time_step} s '
                f'to be a whole number of MuJoCo steps, got timestep = {options.timestep} s'
            )
        self.n_substeps = n_substeps
        self.touch_tolerance = float(touch_tolerance)
        self.min_object_height = min_object_height
        self.stop_on_drop = stop_on_drop
        self.distance_limit = float(distance_limit)
        #: The generated MJCF text.
        self.mjcf = mjcf_from_model(model, options)
        self.mj_model = mujoco.MjModel.from_xml_string(self.mjcf)
        self.mj_data = mujoco.MjData(self.mj_model)
        mj = self.mj_model
        names = model.joint_names
        # MuJoCo's indices: qpos and dof addresses of the joints (model joint order) and the
        # object's free joint; the fingertip geoms (contact order) and bodies; the object's.
        self.joint_qpos = np.array([mj.joint(name).qposadr[0] for name in names])
        self.joint_dofs = np.array([mj.joint(name).dofadr[0] for name in names])
        free = mj.joint(f'{OBJECT_BODY}/free')
        self.object_qpos = int(free.qposadr[0])
        self.object_dof = int(free.dofadr[0])
        self.object_body = int(mj.body(OBJECT_BODY).id)
        self.object_geom = int(mj.geom(f'{OBJECT_BODY}/shape').id)
        self.fingertip_geoms = np.array(
            [mj.geom(fingertip_geom_name(name)).id for name in model.contact_names]
        )
        self.fingertip_bodies = np.array([mj.geom_bodyid[g] for g in self.fingertip_geoms])
        self._jacobian = np.zeros((2, 3, mj.nv))
        self.monitor = EventMonitor.from_model(model)
        self.reset()

    # ----------------------------------------------------------------------------- state
    def reset(self, state: SimState | None = None) -> SimState:
        """Set MuJoCo's state to ``state`` (None: the initial grasp, as the rigid plant's)."""
        mujoco = self._mujoco
        if state is None:
            state = initial_state(self.model, self.config)
        data = self.mj_data
        mujoco.mj_resetData(self.mj_model, data)
        data.qpos[self.joint_qpos] = state.q
        data.qvel[self.joint_dofs] = state.dq
        k, d = self.object_qpos, self.object_dof
        data.qpos[k : k + 3] = state.p_object_in_palm
        x, y, z, w = state.quaternion_object
        data.qpos[k + 3 : k + 7] = (w, x, y, z)
        data.qvel[d : d + 3] = state.twist_object[:3]
        # The free joint's angular velocity is in the body frame.
        data.qvel[d + 3 : d + 6] = state.R_object_to_palm.T @ state.twist_object[3:]
        data.time = state.t
        self._restart(state)
        self._substep_index = 0
        self._slip_distance = np.zeros(self.model.n_contacts)
        #: The last step's report (None before the first step).
        self.last_report: StepReport | None = None
        #: MuJoCo's object acceleration ``(a_o, alpha_o)`` (palm coordinates, m/s², rad/s²)
        #: at the last step's start state under its torque (NaN before the first step).
        self.last_object_acceleration_in_palm = np.full(6, np.nan)
        mujoco.mj_forward(self.mj_model, data)
        self._state = self._read_state()
        self._contacts = self._measure_contacts(0.0)
        return self._state

    def observe(self) -> SimState:
        """Return the current state (palm frame; object twist at its centre of mass)."""
        return self._state

    def contact_report(self) -> ContactReport:
        """Return what MuJoCo measures at the contacts at the current state."""
        return self._contacts

    def _read_state(self) -> SimState:
        data = self.mj_data
        k, d = self.object_qpos, self.object_dof
        w, x, y, z = data.qpos[k + 3 : k + 7]
        quaternion = np.array([x, y, z, w]) / np.linalg.norm((x, y, z, w))
        R_object_to_palm = data.xmat[self.object_body].reshape(3, 3)
        twist = np.concatenate((data.qvel[d : d + 3], R_object_to_palm @ data.qvel[d + 3 : d + 6]))
        return SimState(
            self._t0 + self._step_index * self.time_step,
            data.qpos[self.joint_qpos],
            data.qvel[self.joint_dofs],
            data.qpos[k : k + 3],
            quaternion,
            twist,
        )

    # ------------------------------------------------------------------------------ step
    def step(self, effort: np.ndarray) -> SimState:
        """Hold ``effort`` (m,), N·m, over ``n_substeps`` MuJoCo steps.

        After each MuJoCo step the contacts are measured at the new state and the slip
        distance accumulates slip speed × MuJoCo's timestep.

        Raises:
            RuntimeError: The run has stopped (call :meth:`reset`).
            ValueError: ``effort`` has the wrong shape or is not finite.
        """
        u = self._checked_effort(effort)
        mujoco, mj, data = self._mujoco, self.mj_model, self.mj_data
        start, state0 = self._state, self.grasp_state()
        force = np.full(self.model.wrench_size, np.nan)
        data.ctrl[:] = u
        for substep in range(self.n_substeps):
            mujoco.mj_step(mj, data)
            if substep == 0:
                # mj_step leaves the contacts, forces and accelerations of the state it
                # started from.
                force = self._contact_forces(state0)
                self.last_object_acceleration_in_palm = self._object_acceleration(state0)
            # Contacts and forces at the new state.
            mujoco.mj_forward(mj, data)
            self._substep_index += 1
            if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
                self._stop_reason = NUMERICAL_FAILURE
                break
            self._contacts = self._measure_contacts(self.options.timestep)
        if self._stop_reason is None:
            self._step_index += 1
            self._state = self._read_state()
            self._grasp_state = None
            if self.stop_on_drop and self._contacts.object_dropped:
                self._stop_reason = OBJECT_DROPPED
        margins = self.monitor.margins(state0, force)
        events = self.monitor.events(margins)
        self.log.record(margins, events)
        self.last_report = StepReport(
            start=start,
            state=self._state,
            grasp_state=state0,
            effort=u,
            contact_force=force,
            margins=margins,
            events=events,
            stop_reason=self._stop_reason,
        )
        return self._state

    # -------------------------------------------------------------------------- contacts
    def fingertip_contacts(self) -> Iterator[tuple[int, Any, np.ndarray]]:
        """Each active MuJoCo contact of a fingertip with the object, at the current state.

        Yields ``(i, contact, wrench)``: the fingertip's contact index, MuJoCo's contact, and
        its force and torque in MuJoCo's contact frame (one buffer, rewritten per contact).
        """
        mj, data = self.mj_model, self.mj_data
        wrench = np.zeros(6)
        for c in range(data.ncon):
            contact = data.contact[c]
            i = self._pair(contact)
            if i is None or contact.efc_address < 0:
                continue
            self._mujoco.mj_contactForce(mj, data, c, wrench)
            yield i, contact, wrench

    def _pair(self, contact: Any) -> int | None:
        """Return the index of the fingertip of a MuJoCo contact with the object, or None."""
        geoms = {int(contact.geom1), int(contact.geom2)}
        if self.object_geom not in geoms:
            return None
        geoms.discard(self.object_geom)
        hits = np.flatnonzero(self.fingertip_geoms == geoms.pop()) if geoms else []
        return int(hits[0]) if len(hits) else None

    def _contact_forces(self, state: GraspState) -> np.ndarray:
        """Return MuJoCo's contact wrench on the object in our contact frames, (k,).

        Per contact, at ``state`` (the step's start), ``(f_x, f_y, f_n)`` in
        ``state.R_contact_to_palm`` (z along the fingertip normal into the object), N, summed
        over MuJoCo's contacts of the pair; 0 without one. With a soft-finger model
        (k = 4n) the n torsions follow: the torque MuJoCo's contacts exert on the object
        about our normal ``n_i``, N·m (0 below ``condim`` 4, where MuJoCo has none).
        """
        n = self.model.n_contacts
        force_in_palm = np.zeros((n, 3))
        # A point-contact model reads none of the torque.
        torque_in_palm = np.zeros((n, 3)) if self.model.soft_finger else None
        for i, contact, wrench in self.fingertip_contacts():
            # The wrench of geom1 on geom2, in the contact frame whose rows are its axes
            # (the first the normal from geom1 to geom2); the torque is about the contact
            # point, its first component the torsion about that normal.
            axes = np.asarray(contact.frame).reshape(3, 3).T
            sign = 1.0 if int(contact.geom2) == self.object_geom else -1.0
            force_in_palm[i] += sign * (axes @ wrench[:3])
            if torque_in_palm is not None:
                torque_in_palm[i] += sign * (axes @ wrench[3:])
        force = np.einsum('nji,nj->ni', state.R_contact_to_palm, force_in_palm).ravel()
        if torque_in_palm is None:
            return force
        # The torque about the normal only: condim 6's rolling torques (about the tangents)
        # have no place in our wrench.
        torsion = np.einsum('nj,nj->n', state.R_contact_to_palm[:, :, 2], torque_in_palm)
        return np.concatenate((force, torsion))

    def _object_acceleration(self, state: GraspState) -> np.ndarray:
        """Return the object's acceleration, MuJoCo's ``qacc``, in palm coordinates, (6,).

        The free joint's angular acceleration is in the body frame; in the palm frame it is
        ``R_object_to_palm`` times it (``d/dt (R w_b) = R (w_b_dot + w_b × w_b)``).
        """
        d = self.object_dof
        qacc = self.mj_data.qacc
        return np.concatenate((qacc[d : d + 3], state.R_object_to_palm @ qacc[d + 3 : d + 6]))

    def _measure_contacts(self, dt: float) -> ContactReport:
        """Measure every fingertip's contact at the current (forwarded) state.

        Args:
            dt: Time since the last measurement, s: the slip distance grows by slip speed × dt.
        """
        mujoco, mj, data = self._mujoco, self.mj_model, self.mj_data
        n = self.model.n_contacts
        distance = np.empty(n)
        normal = np.zeros(n)
        tangential = np.zeros(n)
        slip_speed = np.zeros(n)
        for i, geom in enumerate(self.fingertip_geoms):
            distance[i] = mujoco.mj_geomDistance(
                mj, data, int(geom), self.object_geom, self.distance_limit, None
            )
        for i, contact, wrench in self.fingertip_contacts():
            normal[i] += wrench[0]
            tangential[i] += float(np.hypot(wrench[1], wrench[2]))
            # Relative velocity of the fingertip's material point and the object's at the
            # contact point, without its normal component.
            point = np.array(contact.pos)
            mujoco.mj_jac(mj, data, self._jacobian[0], None, point, self.fingertip_bodies[i])
            mujoco.mj_jac(mj, data, self._jacobian[1], None, point, self.object_body)
            v_relative = (self._jacobian[0] - self._jacobian[1]) @ data.qvel
            n_contact = np.array(contact.frame[:3])
            v_tangential = v_relative - (n_contact @ v_relative) * n_contact
            slip_speed[i] = max(slip_speed[i], float(np.linalg.norm(v_tangential)))
        present = (distance <= self.touch_tolerance) | (normal > 0.0)
        slip_speed[~present] = 0.0
        self._slip_distance = self._slip_distance + slip_speed * dt
        height = data.qpos[self.object_qpos + 2]
        dropped = not bool(np.any(present)) or (
            self.min_object_height is not None and height < self.min_object_height
        )
        return ContactReport(
            # From the step count, as the state's time: no round-off accumulation.
            t=self._t0 + self._substep_index * self.options.timestep,
            present=present,
            distance=distance,
            normal_force=normal,
            tangential_force=tangential,
            slip_speed=slip_speed,
            slip_distance=self._slip_distance.copy(),
            object_dropped=bool(dropped),
        )
