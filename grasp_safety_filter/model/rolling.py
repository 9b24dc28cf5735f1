"""Rolling contact: geometry of a fingertip–object contact and Montana's contact kinematics.

For contact i, with ``w = R_palm_to_contact (w_f - w_o)`` the angular velocity of the
fingertip relative to the object in the contact frame (pure rolling: no relative linear
velocity at the contact point), Montana's equations (Murray, Li & Sastry 1994, Section 5.6) read

    xi_cf_dot = M_cf^-1 (K_cf + K~_co)^-1 [-w_y, w_x]
    xi_co_dot = M_co^-1 R_psi (K_cf + K~_co)^-1 [-w_y, w_x]
    psi_dot   = w_z + T_cf M_cf xi_cf_dot + T_co M_co xi_co_dot

with ``K~_co = R_psi K_co R_psi`` and the reflection ``R_psi = [[cos, -sin], [-sin, -cos]]``
(so ``R_psi^-1 = R_psi``). The paper omits the ``w_z`` term and writes rho2 with a typo;
the kernels have the corrected forms, checked against finite differences of the geometric
coordinates in the tests.

:class:`ContactPair` names a contact's two surfaces and :class:`ContactGeometry` holds one
contact's geometry (:meth:`~grasp_safety_filter.model.grasp_model.GraspModel.contact_geometry`).
The model evaluates the equations for all contacts of a grasp in compiled closed forms
(:mod:`~grasp_safety_filter.model.rolling_kernels`,
:mod:`~grasp_safety_filter.model.sphere_object_kernels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grasp_safety_filter.model.surfaces import SphereSurface, Surface


@dataclass(frozen=True)
class ContactGeometry:
    """Where and how fingertip and object touch, computed from the configuration.

    Attributes:
        xi_cf: Fingertip surface coordinates ``(a, b)``, rad.
        xi_co: Object surface coordinates (for a face: ``(u, v)`` in m).
        psi: Angle from the object chart's first axis to the fingertip's, rad.
        penetration: Interpenetration along the normal, m (> 0: overlapping).
        p_contact_in_palm: Contact point on the fingertip surface, (3,).
        R_contact_to_palm: Fingertip Gauss frame at the contact, (3, 3); z points into the
            object.
        R_contact_to_fingertip: Same frame in the fingertip frame (``R_fc``), (3, 3).
    """

    xi_cf: np.ndarray
    xi_co: np.ndarray
    psi: float
    penetration: float
    p_contact_in_palm: np.ndarray
    R_contact_to_palm: np.ndarray
    R_contact_to_fingertip: np.ndarray


class ContactPair:
    """A spherical fingertip rolling on one surface of the object.

    Args:
        fingertip: The fingertip surface, in the fingertip frame (origin at the sphere centre).
        object_surface: The touched object surface, in the object frame.
    """

    def __init__(self, fingertip: SphereSurface, object_surface: Surface) -> None:
        if not isinstance(fingertip, SphereSurface):
            raise TypeError(
                'ContactPair: the fingertip must be a SphereSurface, got '
                f'{type(fingertip).__name__}'
            )
        self.fingertip = fingertip
        self.object_surface = object_surface
