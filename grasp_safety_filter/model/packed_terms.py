"""Every model term of a tick in one compiled pass, written into one flat buffer.

The model's one evaluation of a tick. For spherical fingertips on flat faces (the paper's
cube), :func:`sphere_on_plane_terms` (on a sphere object, :func:`sphere_on_sphere_terms`)
takes Pinocchio's raw hand terms (:meth:`~grasp_safety_filter.model.hand.HandModel.raw_terms`:
the :class:`~grasp_safety_filter.model.hand.RawHandTerms` and
:class:`~grasp_safety_filter.model.hand.FingertipFrames` arguments) and the object's, and runs
in one call the hand's terms in the model's joint order
(:func:`~grasp_safety_filter.model.hand_kernel.hand_in_model_order`), the contact kinematics
(:func:`~grasp_safety_filter.model.rolling_kernels.sphere_on_plane_contacts`,
:func:`~grasp_safety_filter.model.sphere_object_kernels.sphere_on_sphere_contacts`), the
contact dynamics (:mod:`~grasp_safety_filter.model.dynamics_kernel`, around one LAPACK solve
of ``B_ho``) and last :attr:`GraspState.xi_co_ddot
<grasp_safety_filter.model.grasp_state.GraspState.xi_co_ddot>`
(:func:`~grasp_safety_filter.model.rolling_kernels.object_coordinate_rate_terms`), which an
object-workspace barrier reads. Each term goes to its place in one float64 buffer
(:class:`PackedLayout`), from which :class:`~grasp_safety_filter.model.packed_state.
PackedGraspState` hands out read-only views when they are read. A tick's terms are a few
hundred float operations: one call with one output, instead of a call per stage and an
array per term, is most of what saving Python's per-call cost can give. The stages both
kernels share are :mod:`grasp_safety_filter.model.packed_pass`'s.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.hand_kernel import hand_in_model_order
from grasp_safety_filter.model.object_kernel import object_dynamics
from grasp_safety_filter.model.packed_pass import (
    write_grasp_terms,
    write_object_coordinate_acceleration,
)
from grasp_safety_filter.model.rolling_kernels import sphere_on_plane_contacts
from grasp_safety_filter.model.sphere_object_kernels import sphere_on_sphere_contacts


def packed_fields(
    n: int, m: int, torsion: bool = False
) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """Return the buffer's terms in order, with their shapes, for n contacts and m joints.

    The order is the one :func:`sphere_on_plane_terms` and :func:`sphere_on_sphere_terms`
    write. Names are :class:`~grasp_safety_filter.model.grasp_state.GraspState` fields, the contact
    geometry's and rolling rates' fields, and ``*_augmented``: ``[matrix | offset]`` of an
    affine term, (k, m + 1) (``xi_co_ddot_augmented``: :attr:`GraspState.xi_co_ddot
    <grasp_safety_filter.model.grasp_state.GraspState.xi_co_ddot>`). The contact wrench
    has k = 3n entries, or 4n with soft-finger contacts (``torsion``;
    :mod:`~grasp_safety_filter.model.dynamics_kernel`).
    """
    k = 4 * n if torsion else 3 * n
    return (
        ('q', (m,)),
        ('dq', (m,)),
        ('p_object_in_palm', (3,)),
        ('R_object_to_palm', (3, 3)),
        ('twist_object', (6,)),
        ('p_fingertip_in_palm', (n, 3)),
        ('R_fingertip_to_palm', (n, 3, 3)),
        ('twist_fingertip', (n, 6)),
        ('J_fingertip', (n, 6, m)),
        ('M_h', (m, m)),
        ('h_bias', (m,)),
        ('gravity_torque', (m,)),
        ('xi_cf', (n, 2)),
        ('xi_co', (n, 2)),
        ('psi', (n,)),
        ('penetration', (n,)),
        ('p_contact_in_palm', (n, 3)),
        ('R_contact_to_palm', (n, 3, 3)),
        ('R_contact_to_fingertip', (n, 3, 3)),
        ('xi_cf_dot', (n, 2)),
        ('xi_co_dot', (n, 2)),
        ('psi_dot', (n,)),
        ('H_cf', (n, 2, 3)),
        ('H_cf_dot_w', (n, 2)),
        ('sliding_velocity', (n, 2)),
        ('frame_angular_velocity', (n, 3)),
        ('J_h', (k, m)),
        ('G', (6, k)),
        ('Jh_dot_dq', (k,)),
        ('G_dot_T_twist', (k,)),
        ('B_ho', (k, k)),
        ('contact_force_augmented', (k, m + 1)),
        ('joint_acceleration_augmented', (m, m + 1)),
        ('object_acceleration_augmented', (6, m + 1)),
        ('xi_cf_ddot_augmented', (2 * n, m + 1)),
        ('M_o', (6, 6)),
        ('C_o_twist', (6,)),
        ('xi_co_ddot_augmented', (2 * n, m + 1)),
    )


class PackedLayout(NamedTuple):
    """Where each term lies in the buffer.

    Attributes:
        size: The buffer's length (float64 entries).
        places: Per term name, its ``(start, stop, shape)`` in the buffer.
        n_joints: m.
        n_contacts: n.
        torsion: Whether the contacts are soft fingers (4n wrench entries, not 3n).
        torsional_compliance: Soft fingers' relative torsional compliance rho
            (:func:`~grasp_safety_filter.model.wrench_solve.wrench_solve`).
    """

    size: int
    places: dict[str, tuple[int, int, tuple[int, ...]]]
    n_joints: int
    n_contacts: int
    torsion: bool = False
    torsional_compliance: float = 0.0

    def start(self, name: str) -> int:
        """Return the index of a term's first entry (its entries follow in C order)."""
        return self.places[name][0]

    @classmethod
    def of(
        cls, n: int, m: int, torsion: bool = False, torsional_compliance: float = 0.0
    ) -> PackedLayout:
        """Return the layout of :func:`packed_fields` for n contacts and m joints."""
        places = {}
        start = 0
        for name, shape in packed_fields(n, m, torsion):
            stop = start + int(np.prod(shape))
            places[name] = (start, stop, shape)
            start = stop
        return cls(start, places, m, n, torsion, float(torsional_compliance))


@kernel
def sphere_on_plane_terms(
    out: np.ndarray,
    raw: tuple[np.ndarray, ...],
    frames: tuple[np.ndarray, ...],
    joint_index: np.ndarray,
    branches: tuple[np.ndarray, np.ndarray],
    q: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    M_o_in_body: np.ndarray,
    isotropic: bool,
    w_e: np.ndarray,
    surfaces: tuple[np.ndarray, np.ndarray, np.ndarray],
    torsion: bool,
    torsional_compliance: float,
) -> None:
    """Write every term of :func:`packed_fields` into ``out``, in that order.

    Args:
        out: The buffer, (:attr:`PackedLayout.size`,).
        raw: Pinocchio's terms at ``(q, dq)``, in its joint order
            (:class:`~grasp_safety_filter.model.hand.RawHandTerms`).
        frames: Where the fingertip frames hang in Pinocchio's model
            (:class:`~grasp_safety_filter.model.hand.FingertipFrames`).
        joint_index: Pinocchio's index of each of the model's joints, (m,).
        branches: Each joint's and each fingertip's span, (m, 2) and (n, 2)
            (:class:`~grasp_safety_filter.model.hand.Branches`).
        q: Joint angles, (m,), rad.
        dq: Joint velocities, (m,), rad/s.
        p_object_in_palm: Object centre of mass, (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        twist_object: ``(v_o, w_o)``, (6,).
        M_o_in_body: ``M_o`` and ``M_o^-1`` in the object frame, ``blkdiag(mass I3,
            I_body)`` and ``blkdiag(I3 / mass, I_body^-1)``, (2, 6, 6)
            (:attr:`~grasp_safety_filter.model.rigid_object.RigidObject.mass_matrices_in_body`).
        isotropic: Whether ``I_body`` is isotropic (then ``M_o`` is the same in every frame).
        w_e: External wrench on the object, (6,).
        surfaces: Each face's origin in the object frame (n, 3), m; each face's ``[e1, e2,
            n]`` in the object frame (n, 3, 3); each fingertip's radius (n,), m.
        torsion: Soft-finger contacts (:attr:`PackedLayout.torsion`).
        torsional_compliance: Their relative torsional compliance rho.

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular.
    """
    plane_origin, plane_frame, radius = surfaces
    object_terms = object_dynamics(M_o_in_body, isotropic, R_object_to_palm, twist_object)
    hand_terms = hand_in_model_order(raw, frames, joint_index, dq)
    p_f, R_f, _, twist_f = hand_terms[:4]
    contacts = sphere_on_plane_contacts(
        p_f, R_f, twist_f, p_object_in_palm, R_object_to_palm, twist_object,
        plane_origin, plane_frame, radius,
    )
    at, xi_cf_ddot = write_grasp_terms(
        out, object_terms, hand_terms, contacts, branches, q, dq,
        p_object_in_palm, R_object_to_palm, twist_object, w_e, torsion, torsional_compliance,
    )
    write_object_coordinate_acceleration(out, at, contacts, xi_cf_ddot, radius, radius, True)


@kernel
def sphere_on_sphere_terms(
    out: np.ndarray,
    raw: tuple[np.ndarray, ...],
    frames: tuple[np.ndarray, ...],
    joint_index: np.ndarray,
    branches: tuple[np.ndarray, np.ndarray],
    q: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    M_o_in_body: np.ndarray,
    isotropic: bool,
    w_e: np.ndarray,
    surfaces: tuple[np.ndarray, np.ndarray, np.ndarray],
    torsion: bool,
    torsional_compliance: float,
) -> None:
    """Write every term of :func:`packed_fields` into ``out``, for a sphere object.

    :func:`sphere_on_plane_terms` with the contacts of spherical fingertips on a sphere
    (:func:`~grasp_safety_filter.model.sphere_object_kernels.sphere_on_sphere_contacts`):
    the same arguments, with ``surfaces`` each contact's chart of the object sphere
    (n, 3, 3), the object's radius per contact (n,), m, and each fingertip's radius (n,), m.

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular.
        ValueError: A fingertip centre is the object's centre.
    """
    R_chart_to_object, object_radius, radius = surfaces
    object_terms = object_dynamics(M_o_in_body, isotropic, R_object_to_palm, twist_object)
    hand_terms = hand_in_model_order(raw, frames, joint_index, dq)
    p_f, R_f, _, twist_f = hand_terms[:4]
    contacts = sphere_on_sphere_contacts(
        p_f, R_f, twist_f, p_object_in_palm, R_object_to_palm, twist_object,
        R_chart_to_object, object_radius, radius,
    )
    at, xi_cf_ddot = write_grasp_terms(
        out, object_terms, hand_terms, contacts, branches, q, dq,
        p_object_in_palm, R_object_to_palm, twist_object, w_e, torsion, torsional_compliance,
    )
    write_object_coordinate_acceleration(
        out, at, contacts, xi_cf_ddot, radius, object_radius, False
    )
