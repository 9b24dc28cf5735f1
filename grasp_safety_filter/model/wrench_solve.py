"""Soft fingers' contact wrench: ``B_ho f_c = rhs`` with compliant or redundant spin rows.

:mod:`~grasp_safety_filter.model.dynamics_kernel` forms ``B_ho`` and the right-hand side;
point contacts solve them by LAPACK's gesv. Soft fingers add a no-spin row per contact
(after the 3n force rows), which can make ``B_ho`` singular or nearly so, and take
:func:`wrench_solve` instead. :func:`contact_wrench` chooses between the two for the
model's and the simulator's Python callers; the compiled one-pass kernel
(:mod:`~grasp_safety_filter.model.packed_terms`) makes the same choice inside.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgesv

from grasp_safety_filter.model.compiled import kernel

#: Singular values of ``B_ho`` below this fraction of its largest are round-off and dropped
#: by :func:`wrench_solve`: 1e-18 to 1e-16 at the grasps where soft fingers leave an internal
#: torsion undetermined, 1e-8 and more a millisecond of motion away from them.
WRENCH_RCOND = 1e-13


@kernel
def wrench_solve(B_ho: np.ndarray, rhs: np.ndarray, compliance: float) -> np.ndarray:
    """Minimum-norm ``X`` of ``(B_ho + rho D_t) X = rhs``: the contact wrench of soft fingers.

    ``D_t`` is ``B_ho``'s diagonal on the n spin rows (0 on the 3n force rows) and rho the
    relative torsional ``compliance`` (``model.torsional_compliance``; 0: rigid). With rho > 0
    each spin constraint yields as MuJoCo's soft constraints do (their regulariser is about
    ``(1 - d) / d`` of the diagonal, 0.11 at MuJoCo's default impedance d = 0.9): contact i's
    spin acceleration is ``rho (B_ho)_tt tau_i`` instead of 0, and the torsions stay bounded
    where the rigid ones grow without bound (below).

    Rigid no-spin constraints can be redundant: two contacts on opposite faces of a box can
    squeeze the object with equal torsions (``G v = 0``), and where no joint torque reaches
    that internal torsion (``J_h^T v = 0``: fingers that cannot twist about their normals,
    as the paper's at its initial grasp, or whose twist their tangential forces balance, as
    the four-finger box's) ``B_ho`` is singular and the torsion undetermined. With the rigid
    rows (rho = 0) the wrench is then LAPACK's SVD least-squares solution of minimum norm
    (singular values below :data:`WRENCH_RCOND` of the largest dropped): it loads no
    undetermined internal torsion. ``rhs`` need not lie in the range of ``B_ho`` there: its
    velocity terms along v, ``v^T (J_h_dot dq - G_dot^T x_o_dot)``, are not zero while the
    grasp moves, and no finite wrench keeps that spin row, whose acceleration residual the
    least-squares solution leaves (the rigid model's limit at such a grasp; a compliance
    removes it). Where ``B_ho`` is regular, this is ``B_ho^-1 rhs`` (to round-off; point
    contacts never call this). Around
    such grasps ``B_ho`` is nearly singular and the rigid internal torsion is about the joint
    torque over the fingers' small twisting lever: large and sensitive, which is what the
    compliance is for.

    Raises:
        numpy.linalg.LinAlgError: ``B_ho`` or ``rhs`` is not finite, or (rho > 0) the
            regularised matrix is singular.
    """
    if compliance == 0.0:
        return np.linalg.lstsq(B_ho, rhs, rcond=WRENCH_RCOND)[0]
    # Regularised, the matrix is positive definite: B_ho is positive semi-definite, definite
    # on the force rows alone, so each vector of its null space has a torsion entry, which
    # the regulariser weights. LAPACK's LU solve then does, at a third of the SVD's cost.
    k = B_ho.shape[0]
    regularised = B_ho.copy()
    for t in range(3 * (k // 4), k):
        regularised[t, t] += compliance * B_ho[t, t]
    return np.linalg.solve(regularised, rhs)


def contact_wrench(
    B_ho: np.ndarray, rhs: np.ndarray, torsion: bool, compliance: float
) -> np.ndarray:
    """Solve ``B_ho X = rhs`` for the contact wrench (or its affine map).

    Point contacts: LAPACK's gesv (scipy), the solve numpy's would make; soft fingers
    (``torsion``): :func:`wrench_solve` with the relative torsional ``compliance``.

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular (point contacts; the contact forces are
            not determined).
    """
    if torsion:
        return wrench_solve(B_ho, rhs, compliance)
    _, _, solution, info = dgesv(B_ho, rhs)
    if info != 0:
        raise np.linalg.LinAlgError(f'B_ho is singular (LAPACK gesv info {info})')
    return solution
