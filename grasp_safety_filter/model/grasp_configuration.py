"""Solves on a grasp's configuration: fingertips onto the object, joint rates that roll with it.

Both act on a :class:`~grasp_safety_filter.model.grasp_model.GraspModel` through its public
terms; the model's methods of the same names are these functions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from grasp_safety_filter.model.fingertip_workspace import GraspConfigError

if TYPE_CHECKING:  # the model's module imports this one
    from grasp_safety_filter.model.grasp_model import GraspModel


def project_to_contact(
    model: GraspModel,
    q: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    tolerance: float = 1e-13,
    max_iterations: int = 50,
) -> np.ndarray:
    """Smallest joint correction that makes every fingertip touch its surface exactly.

    Gauss–Newton on the penetrations δ_i(q), with ``dδ_i/dq = -n_i^T J_v,i`` (n_i the
    object's outward normal at the contact, J_v,i the fingertip centre's Jacobian).

    Args:
        model: The grasp model (binds its contacts at ``q`` if they are not yet).
        q: Joint angles, (m,), rad.
        p_object_in_palm: Object position in the palm frame, (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        tolerance: Largest penetration or gap left, m.
        max_iterations: Gauss–Newton steps before giving up.

    Returns:
        The corrected joint angles, (m,), rad.

    Raises:
        GraspConfigError: The penetrations are not within ``tolerance`` after
            ``max_iterations``.

    """
    q = np.array(q, dtype=float)
    model.bind_contacts(q, p_object_in_palm, R_object_to_palm)
    for _ in range(max_iterations):
        _, _, J_f = model.hand.fingertip_placements(q)
        delta = np.empty(model.n_contacts)
        jacobian = np.empty((model.n_contacts, model.n_joints))
        geometries = model.contact_geometry(q, p_object_in_palm, R_object_to_palm)
        for i, geometry in enumerate(geometries):
            delta[i] = geometry.penetration
            n_object = -geometry.R_contact_to_palm[:, 2]
            jacobian[i] = -n_object @ J_f[i, :3]
        if np.max(np.abs(delta)) <= tolerance:
            return q
        q -= np.linalg.lstsq(jacobian, delta, rcond=None)[0]
    raise GraspConfigError(
        f'cannot bring every fingertip onto the object: penetrations {delta} m after '
        f'{max_iterations} iterations'
    )


def rolling_joint_velocity(
    model: GraspModel,
    q: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
) -> np.ndarray:
    """Joint velocity that rolls the fingertips with the object, (m,), rad/s.

    Solves ``J_h dq = G^T x_o_dot`` (least-norm when m > 3n) at ``model.state`` of the
    configuration, ``twist_object`` the object's twist (6,). Soft fingers also forbid spin,
    which not every twist allows: the velocity is then the least-squares one of the force
    rows.
    """
    state = model.state(
        0.0, q, np.zeros(model.n_joints), p_object_in_palm, R_object_to_palm, np.zeros(6)
    )
    k = 3 * model.n_contacts
    rhs = state.G[:, :k].T @ np.asarray(twist_object, dtype=float)
    return np.linalg.lstsq(state.J_h[:k], rhs, rcond=None)[0]
