"""Contact surfaces and their differential geometry (Montana 1988; Murray, Li & Sastry ch. 5).

A surface is a smooth orthogonal parameterisation ``c(xi)``, ``xi = (a, b)``, of a body's
boundary, in that body's frame. At every point it has the Gauss frame

    rho1 = c_a / |c_a|,   rho2 = c_b / |c_b|,   n = rho1 × rho2   (outward normal)

(the paper's eq. for R_fc has the typo ``c_a / |c_b|`` for rho2), and the geometric
parameters

    M = diag(|c_a|, |c_b|)                                  metric
    K = [rho1; rho2] [dn/da / |c_a|,  dn/db / |c_b|]       curvature
    T = rho2 · [drho1/da / |c_a|,  drho1/db / |c_b|]       torsion (1 × 2)

which drive the rolling equations (see :mod:`grasp_safety_filter.model.rolling`).
Every surface here gives them in closed form, with their rates along ``xi_dot``.

The classes here describe the surfaces (shape, placement, chart); the closed forms of their
rolling contacts, spherical fingertips on flat faces or on a sphere, are evaluated in
compiled kernels (:mod:`~grasp_safety_filter.model.rolling_kernels`,
:mod:`~grasp_safety_filter.model.sphere_object_kernels`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.model.arrays import read_only


class Surface:
    """A body's contact surface: its chart, in the frame of the body it bounds.

    A description (shape, placement, chart); the rolling kinematics of its closed forms
    are evaluated in the compiled contact kernels.
    """


class SphereSurface(Surface):
    """A sphere of radius R about the body origin, in the paper's chart (Section V).

        c(a, b) = [-R cos a cos b,  R sin a,  -R cos a sin b]

    For a fingertip frame with z out of the tip, ``-pi < b < 0`` is the hemisphere
    ``z > 0`` and ``(a, b) = (0, -pi/2)`` is the tip. Closed forms:

        c_a = R [sin a cos b, cos a, sin a sin b],   |c_a| = R
        c_b = R cos a [sin b, 0, -cos b],             |c_b| = R |cos a|
        n = c / R,  M = diag(R, R cos a),  K = I / R,  T = [0, -tan(a) / R]

    The chart is singular at ``a = ±pi/2`` (|c_b| = 0), so workspace bounds on ``a`` need a
    margin from ``±pi/2``; ``b`` jumps by 2 pi across the half circle ``b = ±pi``.

    ``R_chart_to_body`` turns the chart in the body frame: the formulas above hold in a chart
    frame K, and every point, tangent and frame is returned as ``R_chart_to_body`` times its
    K components (metric, curvature and torsion do not change). The chart's centre
    ``(a, b) = (0, -pi/2)`` is then the body direction ``R_chart_to_body e_z``, its poles
    ``±R_chart_to_body e_y``. A fingertip uses the identity (the paper's chart in F_i); a
    sphere object turns one chart per contact so that its centre is the contact's initial
    normal (:func:`grasp_safety_filter.model.object_shapes.sphere_chart_centred_on`).
    """

    def __init__(self, radius: float, R_chart_to_body: np.ndarray | None = None) -> None:
        if not np.isfinite(radius) or radius <= 0.0:
            raise ValueError(
                f'SphereSurface: radius must be a positive finite length, got {radius!r}'
            )
        self.radius = float(radius)
        if R_chart_to_body is not None:
            R_chart_to_body = np.array(R_chart_to_body, dtype=float)
            if R_chart_to_body.shape != (3, 3) or not np.allclose(
                R_chart_to_body @ R_chart_to_body.T, np.eye(3), atol=1e-12
            ):
                raise ValueError(
                    'SphereSurface: R_chart_to_body must be a rotation matrix, got '
                    f'{R_chart_to_body!r}'
                )
            R_chart_to_body = read_only(R_chart_to_body)
        self.R_chart_to_body = R_chart_to_body


class FlatSurface(Surface):
    """A plane through ``origin`` spanned by orthonormal ``e1, e2``, outward normal ``e1 × e2``.

    c(u, v) = origin + u e1 + v e2,   M = I,  K = 0,  T = 0   (u, v in m)

    The chart is the whole plane; ``half_width`` bounds the face itself (the rectangle
    ``|u| <= h_u, |v| <= h_v`` about ``origin`` for ``half_width = (h_u, h_v)``, a square for
    one number; infinite by default) for :meth:`outside_distance`.
    """

    def __init__(
        self,
        origin: np.ndarray,
        e1: np.ndarray,
        e2: np.ndarray,
        half_width: float | tuple[float, float] = np.inf,
    ) -> None:
        origin, e1, e2 = (np.asarray(x, dtype=float) for x in (origin, e1, e2))
        for name, vec in (('origin', origin), ('e1', e1), ('e2', e2)):
            if vec.shape != (3,) or not np.all(np.isfinite(vec)):
                raise ValueError(f'FlatSurface: {name} must be a finite 3-vector, got {vec!r}')
        if abs(np.linalg.norm(e1) - 1) > 1e-12 or abs(np.linalg.norm(e2) - 1) > 1e-12:
            raise ValueError(f'FlatSurface: e1, e2 must be unit vectors, got {e1}, {e2}')
        if abs(e1 @ e2) > 1e-12:
            raise ValueError(f'FlatSurface: e1, e2 must be orthogonal, got e1·e2 = {e1 @ e2}')
        half_widths = np.broadcast_to(np.asarray(half_width, dtype=float), (2,)).copy()
        if not np.all(half_widths > 0.0):
            raise ValueError(f'FlatSurface: half_width must be > 0, got {half_width!r}')
        self.origin = origin
        #: ``(h_u, h_v)``: the face is ``|u| <= h_u, |v| <= h_v``, m.
        self.half_widths = read_only(half_widths)
        self._frame = np.column_stack([e1, e2, np.cross(e1, e2)])

    def outside_distance(self, xi: np.ndarray) -> float:
        """How far ``(u, v)`` lies beyond the face's edges, ``max(|u| - h_u, |v| - h_v)``, m.

        At most 0 on the face.
        """
        return float(np.max(np.abs(np.asarray(xi, dtype=float)) - self.half_widths))

    @property
    def normal(self) -> np.ndarray:
        """Outward unit normal ``e1 × e2``, body frame."""
        return self._frame[:, 2]

    @property
    def axes(self) -> np.ndarray:
        """``[e1, e2, e1 × e2]`` as columns, (3, 3), body frame: the (constant) Gauss frame."""
        return self._frame.copy()


CUBE_FACE_AXES: dict[str, tuple[int, float]] = {
    '+x': (0, 1.0),
    '-x': (0, -1.0),
    '+y': (1, 1.0),
    '-y': (1, -1.0),
    '+z': (2, 1.0),
    '-z': (2, -1.0),
}


def face_label(plane: FlatSurface) -> str | None:
    """Label (``"+x"``...) of the box face whose outward normal ``plane`` has, else None."""
    for label, (axis, sign) in CUBE_FACE_AXES.items():
        if plane.normal[axis] * sign > 1.0 - 1e-9:
            return label
    return None


def box_face(label: str, edge_lengths: Sequence[float]) -> FlatSurface:
    """Return the face ``label`` (``"+x"``, ``"-y"``, ...) of a box centred at the origin.

    ``edge_lengths = (l_x, l_y, l_z)``, m, along the object frame's axes. The face ``±k`` lies
    at ``±l_k / 2`` along axis k; its chart axes follow the cyclic order so that ``e1 × e2``
    is the outward normal, ``(u, v) = (0, 0)`` is the face centre, and the face is
    ``|u| <= l_e1 / 2, |v| <= l_e2 / 2`` (e1, e2 the face's in-plane axes).
    """
    if label not in CUBE_FACE_AXES:
        raise ValueError(f'box face: expected one of {list(CUBE_FACE_AXES)}, got {label!r}')
    lengths = np.asarray(edge_lengths, dtype=float)
    if lengths.shape != (3,) or not np.all(np.isfinite(lengths)) or not np.all(lengths > 0.0):
        raise ValueError(
            f'box face: edge lengths must be three positive lengths, got {edge_lengths!r}'
        )
    axis, sign = CUBE_FACE_AXES[label]
    basis = np.eye(3)
    normal = sign * basis[axis]
    first, second = (axis + 1) % 3, (axis + 2) % 3
    if sign < 0:
        first, second = second, first
    half = 0.5 * lengths
    return FlatSurface(
        half[axis] * normal,
        basis[first],
        basis[second],
        half_width=(float(half[first]), float(half[second])),
    )


def cube_face(label: str, edge_length: float) -> FlatSurface:
    """Return the face ``label`` of a cube of edge ``edge_length`` (:func:`box_face`)."""
    if not np.isfinite(edge_length) or edge_length <= 0.0:
        raise ValueError(f'cube face: edge length must be positive, got {edge_length!r}')
    if label not in CUBE_FACE_AXES:
        raise ValueError(f'cube face: expected one of {list(CUBE_FACE_AXES)}, got {label!r}')
    return box_face(label, (edge_length,) * 3)
