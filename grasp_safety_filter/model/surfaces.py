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

The per-tick model evaluates the same closed forms for spherical fingertips on flat faces
or on a sphere in compiled kernels (:mod:`~grasp_safety_filter.model.rolling_kernels`,
:mod:`~grasp_safety_filter.model.sphere_object_kernels`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.model.arrays import read_only


class Surface(ABC):
    """A smooth, orthogonally parameterised surface in the frame of the body it bounds."""

    @abstractmethod
    def point(self, xi: np.ndarray) -> np.ndarray:
        """Surface point ``c(xi)``, shape (3,), m, body frame."""

    @abstractmethod
    def tangents(self, xi: np.ndarray) -> np.ndarray:
        """``[c_a, c_b]`` as columns, shape (3, 2), body frame."""

    @abstractmethod
    def frame(self, xi: np.ndarray) -> np.ndarray:
        """Gauss frame ``R_contact_to_body = [rho1, rho2, n]``, shape (3, 3)."""

    @abstractmethod
    def frame_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Time derivative of :meth:`frame` along ``xi_dot``, shape (3, 3)."""

    @abstractmethod
    def metric(self, xi: np.ndarray) -> np.ndarray:
        """Metric tensor M, shape (2, 2) (diagonal for orthogonal charts)."""

    @abstractmethod
    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Time derivative of M along ``xi_dot``, shape (2, 2)."""

    @abstractmethod
    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """Curvature tensor K, shape (2, 2), 1/m (positive for convex surfaces)."""

    @abstractmethod
    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Time derivative of K along ``xi_dot``, shape (2, 2)."""

    @abstractmethod
    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """Torsion tensor T, shape (2,) (a 1 × 2 row)."""

    @abstractmethod
    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, float]:
        """Coordinates of the surface point nearest to ``p_in_body`` and its signed distance.

        Returns:
            ``(xi, distance)``: distance (m) along the outward normal, positive outside.
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

    def _to_body(self, chart_components: np.ndarray) -> np.ndarray:
        """``R_chart_to_body @ x`` (``x`` itself without a turned chart)."""
        if self.R_chart_to_body is None:
            return chart_components
        return self.R_chart_to_body @ chart_components

    def point(self, xi: np.ndarray) -> np.ndarray:
        """``c = R (-cos a cos b, sin a, -cos a sin b)``."""
        a, b = xi
        r = self.radius
        return self._to_body(
            np.array([-r * np.cos(a) * np.cos(b), r * np.sin(a), -r * np.cos(a) * np.sin(b)])
        )

    def tangents(self, xi: np.ndarray) -> np.ndarray:
        """``c_a = R (sin a cos b, cos a, sin a sin b)``, ``c_b = R cos a (sin b, 0, -cos b)``."""
        a, b = xi
        r = self.radius
        sa, ca, sb, cb = np.sin(a), np.cos(a), np.sin(b), np.cos(b)
        return self._to_body(r * np.array([[sa * cb, ca * sb], [ca, 0.0], [sa * sb, -ca * cb]]))

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """``rho1 = c_a / R``, ``rho2 = (sin b, 0, -cos b)``, ``n = c / R``."""
        a, b = xi
        sa, ca, sb, cb = np.sin(a), np.cos(a), np.sin(b), np.cos(b)
        rho1 = [sa * cb, ca, sa * sb]
        rho2 = [sb, 0.0, -cb]
        normal = [-ca * cb, sa, -ca * sb]
        return self._to_body(np.array([rho1, rho2, normal]).T)

    def frame_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Differentiate :meth:`frame` along ``xi_dot`` (entrywise chain rule)."""
        a, b = xi
        da, db = xi_dot
        sa, ca, sb, cb = np.sin(a), np.cos(a), np.sin(b), np.cos(b)
        rho1_dot = [ca * cb * da - sa * sb * db, -sa * da, ca * sb * da + sa * cb * db]
        rho2_dot = [cb * db, 0.0, sb * db]
        normal_dot = [sa * cb * da + ca * sb * db, ca * da, sa * sb * da - ca * cb * db]
        return self._to_body(np.array([rho1_dot, rho2_dot, normal_dot]).T)

    def metric(self, xi: np.ndarray) -> np.ndarray:
        """``M = diag(R, R cos a)``."""
        return np.diag([self.radius, self.radius * np.cos(xi[0])])

    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """``M_dot = diag(0, -R sin(a) a_dot)``."""
        return np.diag([0.0, -self.radius * np.sin(xi[0]) * xi_dot[0]])

    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """``K = I / R``."""
        return np.eye(2) / self.radius

    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """``K_dot = 0``."""
        return np.zeros((2, 2))

    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """``T = (0, -tan(a) / R)``."""
        return np.array([0.0, -np.tan(xi[0]) / self.radius])

    def coordinates_of_normal(self, normal: np.ndarray) -> np.ndarray:
        """Inverse Gauss map: the ``(a, b)`` whose outward normal is ``normal`` (unit, (3,)).

        ``a = asin(n_y)``, ``b = atan2(-n_z, -n_x)`` (b in (-pi, pi]), with ``n`` in chart
        components ``R_chart_to_body^T normal``.
        """
        if self.R_chart_to_body is not None:
            normal = self.R_chart_to_body.T @ normal
        a = np.arcsin(np.clip(normal[1], -1.0, 1.0))
        b = np.arctan2(-normal[2], -normal[0])
        return np.array([a, b])

    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, float]:
        """Radial projection: ``xi`` of the point's direction, distance ``|p| - R``."""
        distance_to_centre = float(np.linalg.norm(p_in_body))
        if distance_to_centre == 0.0:
            raise ValueError("SphereSurface.closest_point: the point is the sphere's centre")
        xi = self.coordinates_of_normal(p_in_body / distance_to_centre)
        return xi, distance_to_centre - self.radius


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

    def point(self, xi: np.ndarray) -> np.ndarray:
        """``c = origin + u e1 + v e2``."""
        return self.origin + self._frame[:, :2] @ xi

    def tangents(self, xi: np.ndarray) -> np.ndarray:
        """``[e1, e2]``."""
        return self._frame[:, :2].copy()

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """``[e1, e2, e1 × e2]``, constant."""
        return self._frame.copy()

    def frame_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero: the frame is constant."""
        return np.zeros((3, 3))

    def metric(self, xi: np.ndarray) -> np.ndarray:
        """``M = I``."""
        return np.eye(2)

    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero."""
        return np.zeros((2, 2))

    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """``K = 0``."""
        return np.zeros((2, 2))

    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero."""
        return np.zeros((2, 2))

    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """``T = 0``."""
        return np.zeros(2)

    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, float]:
        """Orthogonal projection: ``xi = (e1, e2) · (p - o)``, distance ``n · (p - o)``."""
        offset = np.asarray(p_in_body, dtype=float) - self.origin
        return self._frame[:, :2].T @ offset, float(self.normal @ offset)


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
