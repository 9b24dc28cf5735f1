"""Oracle (tests only): the surfaces' differential geometry in numpy closed forms.

Every chart's point, tangents, Gauss frame, metric, curvature, torsion and their rates
(Montana 1988; the formulas in the docstrings of :mod:`grasp_safety_filter.model.surfaces`),
for the per-contact and stacked rolling oracles (:mod:`oracle_rolling`, :mod:`model_oracles`).
:func:`geometry_of` gives the oracle of a model surface.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface, Surface


class SphereGeometry(SphereSurface):
    """:class:`SphereSurface` with its closed forms (the class docstring's)."""

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


class FlatGeometry(FlatSurface):
    """:class:`FlatSurface` with its closed forms: ``M = I``, ``K = 0``, ``T = 0``."""

    def point(self, xi: np.ndarray) -> np.ndarray:
        """``c = origin + u e1 + v e2``."""
        return self.origin + self.axes[:, :2] @ xi

    def tangents(self, xi: np.ndarray) -> np.ndarray:
        """``[e1, e2]``."""
        return self.axes[:, :2].copy()

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """``[e1, e2, e1 × e2]``, constant."""
        return self.axes.copy()

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
        return self.axes[:, :2].T @ offset, float(self.normal @ offset)


def geometry_of(surface: Surface) -> SphereGeometry | FlatGeometry:
    """Return the oracle of ``surface`` (itself if it is one already)."""
    if isinstance(surface, (SphereGeometry, FlatGeometry)):
        return surface
    if isinstance(surface, SphereSurface):
        return SphereGeometry(surface.radius, surface.R_chart_to_body)
    if isinstance(surface, FlatSurface):
        axes = surface.axes
        return FlatGeometry(
            surface.origin, axes[:, 0], axes[:, 1], tuple(surface.half_widths.tolist())
        )
    raise TypeError(f'no oracle for {type(surface).__name__}')
