"""The hand–object–contact model: hand, object and rolling contacts assembled.

The equations (DESIGN.md §3; Shaw-Cortez et al., eqs. 1, 2, 4, 17):

    M_h ddq + C_h dq = -J_h^T f_c + tau_e + u          (hand, tau_e = -g(q))
    M_o x_o_ddot + C_o x_o_dot = G f_c + w_e            (object)
    J_h dq = G^T x_o_dot                                (rolling without slipping)

    J_h,i = R_cp,i [I, -(p_fc,i)×] J_s,i,   G_i = [R_pc,i; (p_c,i - p_o)× R_pc,i]

Differentiating the rolling constraint once and substituting both dynamics makes the
contact force affine in the torque:

    B_ho f_c = J_h M_h^-1 (u - C_h dq - g) + J_h_dot dq - G_dot^T x_o_dot
               + G^T M_o^-1 (C_o x_o_dot - w_e),    B_ho = J_h M_h^-1 J_h^T + G^T M_o^-1 G

and with it ``ddq``, ``x_o_ddot`` and the fingertip and object contact coordinates'
second derivatives. ``J_h_dot`` and ``G_dot`` are total time derivatives along the rolling
motion: they include the motion of the contact point over the fingertip and the rotation of
the contact frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.model import grasp_configuration
from grasp_safety_filter.model.contact_surfaces import compiled_contacts, CompiledContacts
from grasp_safety_filter.model.fingertip_workspace import FingertipWorkspace, GraspConfigError
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.hand import HandModel
from grasp_safety_filter.model.object_shapes import ObjectShape
from grasp_safety_filter.model.packed_state import packed_state
from grasp_safety_filter.model.packed_terms import PackedLayout
from grasp_safety_filter.model.per_contact import (
    friction_coefficients,
    torsional_friction_coefficients,
)
from grasp_safety_filter.model.rigid_object import RigidObject
from grasp_safety_filter.model.rolling import ContactGeometry, ContactPair
from grasp_safety_filter.model.surfaces import SphereSurface

__all__ = ['FingertipWorkspace', 'GraspConfigError', 'GraspModel']


class GraspModel:
    """A hand grasping a rigid object at n rolling point contacts with friction.

    Args:
        hand: Kinematics and dynamics of the hand.
        rigid_object: The grasped object.
        contacts: One fingertip–object surface pair per fingertip, in the hand's fingertip
            frame order; None to choose them at the first configuration the model is given
            (:meth:`bind_contacts`), from ``object_shape``.
        contact_names: A name per contact (e.g. the finger's).
        friction_coefficient: Coulomb friction coefficient mu (> 0): one for every contact
            or one per contact.
        fingertip_workspace: Admissible fingertip coordinates (one box or one per contact).
        object_shape: The object's shape, which gives the surfaces when ``contacts`` is None.
        declared_faces: Per contact, a face label of a box to use as declared, or None for the
            face nearest to the fingertip (with ``contacts`` None).
        palm_frame: Name of the palm frame P (the frame_id of poses in P).
        object_frame: Name of the object frame O.
        torsional_friction: Torsional friction mu_t (m), one for every contact or one per
            contact: 0 for point contacts with friction (the paper's model), > 0 for soft
            fingers, which also transmit a torque about the normal, ``|tau_n| <= mu_t f_n``,
            and do not spin on the object (the contact wrench then has 4n entries:
            :mod:`~grasp_safety_filter.model.dynamics_kernel`).
        torsional_compliance: Soft fingers' relative torsional compliance rho >= 0 (0: rigid
            no-spin constraints; :func:`~grasp_safety_filter.model.wrench_solve.wrench_solve`).
    """

    def __init__(
        self,
        hand: HandModel,
        rigid_object: RigidObject,
        contacts: Sequence[ContactPair] | None,
        contact_names: Sequence[str],
        friction_coefficient: float | Sequence[float],
        fingertip_workspace: FingertipWorkspace,
        *,
        object_shape: ObjectShape | None = None,
        declared_faces: Sequence[str | None] | None = None,
        palm_frame: str = 'palm',
        object_frame: str = 'object',
        torsional_friction: float | Sequence[float] = 0.0,
        torsional_compliance: float = 0.1,
    ) -> None:
        n = len(hand.frame_ids)
        if contacts is not None and len(contacts) != n:
            raise GraspConfigError(
                f'model: expected one contact per fingertip frame ({n} frames), got '
                f'{len(contacts)}'
            )
        if contacts is None and object_shape is None:
            raise GraspConfigError('model: expected the contacts or the object shape, got neither')
        if len(contact_names) != n:
            raise GraspConfigError(
                f'model: expected one fingertip frame and one name per contact ({n} contacts), '
                f'got {len(hand.frame_ids)} frames and {len(contact_names)} names'
            )
        if hand.n_joints < 3 * n:
            raise GraspConfigError(
                f'model.joint_names: a hand with n = {n} contacts needs at least 3n = {3 * n} '
                f"joints (the paper's Assumption 1), got {hand.n_joints}"
            )
        self.hand = hand
        self.object = rigid_object
        #: mu_t per contact, (n,), m, read-only; None for point contacts with friction.
        self.torsional_friction = torsional_friction_coefficients(
            torsional_friction, contact_names
        )
        rho = float(torsional_compliance)
        if not (math.isfinite(rho) and rho >= 0.0):
            raise GraspConfigError(
                f'model.torsional_compliance: expected a finite number >= 0, got {rho!r}'
            )
        self._torsional_compliance = rho
        self.object_shape = object_shape
        self.declared_faces = list(declared_faces) if declared_faces is not None else [None] * n
        self._contacts: list[ContactPair] | None = None
        self._compiled_contacts: CompiledContacts | None = None
        self._packed_layout: PackedLayout | None = None
        if contacts is not None:
            self._set_contacts(contacts)
        self.contact_names = list(contact_names)
        #: mu_i per contact, (n,), read-only (one value given applies to every contact).
        self.friction_coefficient = friction_coefficients(friction_coefficient, contact_names)
        self.fingertip_workspace = fingertip_workspace
        self.palm_frame = palm_frame
        self.object_frame = object_frame

    # ----------------------------------------------------------------------------- contacts
    def _set_contacts(self, contacts: Sequence[ContactPair]) -> None:
        """Take the contact pairs and the compiled pass's kernel and layout for them.

        Raises:
            GraspConfigError: The pairs are not spherical fingertips on flat faces or on a
                sphere about the object's centre (the surfaces the model implements).
        """
        try:
            compiled = compiled_contacts(contacts)
        except ValueError as error:
            raise GraspConfigError(f'model: contacts: {error}') from None
        self._contacts = list(contacts)
        self._compiled_contacts = compiled
        self._packed_layout = PackedLayout.of(
            len(self._contacts), self.hand.n_joints, self.soft_finger, self.torsional_compliance
        )

    @property
    def soft_finger(self) -> bool:
        """Whether the contacts are soft fingers (a torque about each normal, no spin)."""
        return self.torsional_friction is not None

    @property
    def torsional_compliance(self) -> float:
        """Soft fingers' relative torsional compliance rho (0: rigid), read-only.

        Read-only: the compiled pass's layout takes it when the contacts are bound.
        """
        return self._torsional_compliance

    @property
    def wrench_size(self) -> int:
        """Entries k of the contact wrench f_c: 3n, or 4n with soft fingers."""
        n = len(self.contact_names)
        return 4 * n if self.soft_finger else 3 * n

    @property
    def contacts_bound(self) -> bool:
        """Whether every contact's object surface is chosen."""
        return self._contacts is not None

    @property
    def contacts(self) -> list[ContactPair]:
        """The fingertip–object surface pairs, in contact order.

        Raises:
            GraspConfigError: They are chosen at a configuration and none was given yet.
        """
        if self._contacts is None:
            raise GraspConfigError(
                'model: the contact surfaces are chosen at the first configuration (nearest '
                'box face, sphere chart centred on the contact), and none was given yet: call '
                'bind_contacts(q, p_o, R_po) or state(...) first'
            )
        return self._contacts

    def bind_contacts(
        self, q: np.ndarray, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray
    ) -> None:
        """Choose each contact's object surface at ``(q, p_o, R_po)``; no-op once chosen.

        A declared face is used as declared; otherwise
        :meth:`~grasp_safety_filter.model.object_shapes.ObjectShape.surface_at` the fingertip
        sphere's centre in the object frame, ``R_po^T (p_f,i - p_o)``: the nearest box face,
        or the sphere in a chart centred on the contact.
        """
        if self._contacts is not None:
            return
        p_f, _, _ = self.hand.fingertip_placements(np.asarray(q, dtype=float))
        p_centres = (p_f - np.asarray(p_object_in_palm, dtype=float)) @ np.asarray(
            R_object_to_palm, dtype=float
        )
        contacts = []
        for tip, face, name, p in zip(
            self.hand.fingertips, self.declared_faces, self.contact_names, p_centres, strict=True
        ):
            try:
                surface = (
                    self.object_shape.face(face) if face else self.object_shape.surface_at(p)
                )
            except ValueError as error:
                raise GraspConfigError(f'model: contact {name!r}: {error}') from None
            contacts.append(ContactPair(SphereSurface(tip.radius), surface))
        self._set_contacts(contacts)

    # ----------------------------------------------------------------------------- loading
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], base_dir: Path | str = '.') -> GraspModel:
        """Build from validated ``model.*`` parameters (dotted names, see io/schemas/model.py).

        See :func:`grasp_safety_filter.model.grasp_parameters.grasp_model_from_parameters`.
        """
        from grasp_safety_filter.model.grasp_parameters import grasp_model_from_parameters

        return grasp_model_from_parameters(cls, params, base_dir)

    @classmethod
    def from_parameter_file(
        cls, path: Path | str, node_name: str = 'hand_sim_node'
    ) -> tuple[GraspModel, dict[str, Any]]:
        """Load a ROS 2 parameter file, validate it against a node's schema, build the model.

        Returns:
            The model and the node's validated parameters (defaults filled in).
        """
        from grasp_safety_filter.io.schemas import load_node_parameters

        path = Path(path)
        params = load_node_parameters(path, node_name)
        return cls.from_parameters(params, path.parent), params

    # -------------------------------------------------------------------------- properties
    @property
    def joint_names(self) -> list[str]:
        """Joint names in command order."""
        return self.hand.joint_names

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        return self.hand.n_joints

    @property
    def n_contacts(self) -> int:
        """Number of contacts n."""
        return len(self.hand.frame_ids)

    @property
    def joint_lower_limits(self) -> np.ndarray:
        """q_min from the URDF, (m,), rad."""
        return self.hand.joint_lower_limits

    @property
    def joint_upper_limits(self) -> np.ndarray:
        """q_max from the URDF, (m,), rad."""
        return self.hand.joint_upper_limits

    @property
    def effort_limits(self) -> np.ndarray:
        """Actuator torque limits from the URDF (|u_j| ≤ limit), (m,), N·m."""
        return self.hand.effort_limits

    # ------------------------------------------------------------------------ configuration
    def contact_geometry(
        self, q: np.ndarray, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray
    ) -> list[ContactGeometry]:
        """Contact coordinates and frames of every contact at a configuration.

        The compiled contact geometry of the per-tick terms
        (:meth:`~grasp_safety_filter.model.contact_surfaces.CompiledContacts.geometry`).
        """
        self.bind_contacts(q, p_object_in_palm, R_object_to_palm)
        p_f, R_f, _ = self.hand.fingertip_placements(np.asarray(q, dtype=float))
        return self._compiled_contacts.geometry(p_f, R_f, p_object_in_palm, R_object_to_palm)

    #: Smallest joint correction that makes every fingertip touch its surface exactly
    #: (:func:`~grasp_safety_filter.model.grasp_configuration.project_to_contact`).
    project_to_contact = grasp_configuration.project_to_contact

    def check_grasp(
        self,
        q: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        tolerance: float | None = None,
    ) -> None:
        """Raise GraspConfigError unless ``(q, p_o, R_po)`` is a valid grasp.

        See :func:`grasp_safety_filter.model.grasp_check.check_grasp` (joint limits, gap or
        penetration within ``tolerance`` m, default ``GAP_TOLERANCE``, contacts on their
        faces and in the fingertip workspace, M_h, J_h and G).
        """
        from grasp_safety_filter.model.grasp_check import check_grasp, GAP_TOLERANCE

        gap = GAP_TOLERANCE if tolerance is None else tolerance
        check_grasp(self, q, p_object_in_palm, R_object_to_palm, gap)

    #: Joint velocity that rolls the fingertips with the object, ``J_h dq = G^T x_o_dot``
    #: (:func:`~grasp_safety_filter.model.grasp_configuration.rolling_joint_velocity`).
    rolling_joint_velocity = grasp_configuration.rolling_joint_velocity

    def total_energy(self, state: GraspState) -> float:
        """Kinetic plus gravitational potential energy of hand and object, J."""
        return self.hand.energy(state.q, state.dq) + self.object.energy(
            state.p_object_in_palm, state.R_object_to_palm, state.twist_object
        )

    # ------------------------------------------------------------------------------- state
    def state(
        self,
        t: float,
        q: np.ndarray,
        dq: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        twist_object: np.ndarray,
    ) -> GraspState:
        """Every model term at one instant (see :class:`GraspState`), in one compiled pass.

        All contacts are evaluated together, and the torque-affine terms as augmented
        matrices ``[matrix | offset]`` acting on ``(u, 1)``, into one buffer whose views are
        the fields (:func:`~grasp_safety_filter.model.packed_state.packed_state`).

        A state whose terms are not finite (an input that is not, or terms that overflow)
        has NaN contact wrench and accelerations.

        Raises:
            numpy.linalg.LinAlgError: ``B_ho`` is singular.
            ValueError: An input's shape is not the model's, or a fingertip centre is a
                sphere object's centre.
        """
        if self._contacts is None:
            self.bind_contacts(q, p_object_in_palm, R_object_to_palm)
        return packed_state(
            self.hand,
            self.object,
            self._compiled_contacts,
            self._packed_layout,
            (t, q, dq, p_object_in_palm, R_object_to_palm, twist_object),
        )


def state_of(model: Any, sample: Any) -> GraspState:
    """Return ``model.state`` at a sample of the plant (a simulator state, a recorded tick).

    ``sample`` has ``t``, ``q``, ``dq``, ``p_object_in_palm``, ``R_object_to_palm`` and
    ``twist_object``; ``model`` is a :class:`GraspModel` (or anything with its ``state``).
    """
    s = sample
    return model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
