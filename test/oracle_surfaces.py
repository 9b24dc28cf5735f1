"""Oracle (tests only): k surfaces of one kind at stacked coordinates ``xi`` (k, 2), numpy.

The closed forms of :mod:`grasp_safety_filter.model.surfaces`, one numpy call per term for
all contacts, for any mix of surfaces (:class:`SurfaceList` through the per-surface
interface): :mod:`model_oracles`' stacked contact kinematics.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np
from oracle_geometry import geometry_of
from stacked_arrays import matvec

from grasp_safety_filter.model.arrays import read_only
from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface, Surface


def _sin_cos(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(sin a, cos a, sin b, cos b)`` of stacked coordinates ``xi`` (k, 2), each (k,)."""
    s, c = np.sin(xi), np.cos(xi)
    return s[:, 0], c[:, 0], s[:, 1], c[:, 1]


class SurfaceStack(ABC):
    """k surfaces of one kind, evaluated together at stacked coordinates ``xi``, shape (k, 2).

    Row j of every result is the corresponding :class:`Surface` method of surface j at
    ``xi[j]``, with the same closed forms. Charts are orthogonal, so metrics are returned as
    their diagonals ``(|c_a|, |c_b|)``, shape (k, 2). Results may be shared read-only arrays.

    Attributes:
        flat: Every surface is a plane (``K = 0``, ``T = 0`` everywhere), so callers can drop
            the curvature and torsion terms.
    """

    flat: bool = False

    @abstractmethod
    def frame(self, xi: np.ndarray) -> np.ndarray:
        """Gauss frames ``[rho1, rho2, n]``, (k, 3, 3)."""

    @abstractmethod
    def metric(self, xi: np.ndarray) -> np.ndarray:
        """Metric diagonals ``(|c_a|, |c_b|)``, (k, 2)."""

    @abstractmethod
    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Time derivatives of the metric diagonals, (k, 2)."""

    @abstractmethod
    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """Curvature tensors, (k, 2, 2)."""

    @abstractmethod
    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Time derivatives of the curvature tensors, (k, 2, 2)."""

    @abstractmethod
    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """Torsion rows, (k, 2)."""

    @abstractmethod
    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest surface points to ``p_in_body`` (k, 3).

        Returns:
            Their coordinates (k, 2) and signed distances (k,), m (positive outside).
        """


class SphereStack(SurfaceStack):
    """Spheres of radii ``R_j`` in the chart of :class:`SphereSurface` (same closed forms)."""

    def __init__(self, spheres: Sequence[SphereSurface]) -> None:
        self.radius = np.array([sphere.radius for sphere in spheres])
        k = self.radius.size
        # Turned charts (a sphere object's): R_chart_to_body per sphere, else None.
        turned = [sphere.R_chart_to_body for sphere in spheres]
        self._rotation = (
            None
            if all(R is None for R in turned)
            else read_only(np.array([np.eye(3) if R is None else R for R in turned]))
        )
        self._zero = read_only(np.zeros(k))
        self._curvature = read_only(np.eye(2) / self.radius[:, None, None])
        self._zeros = read_only(np.zeros((k, 2, 2)))

    @property
    def R_chart_to_body(self) -> np.ndarray:
        """Each sphere's chart orientation in its body, (k, 3, 3): the identity if not turned."""
        if self._rotation is None:
            return np.tile(np.eye(3), (self.radius.size, 1, 1))
        return self._rotation

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """Compute :meth:`SphereSurface.frame` of each sphere."""
        sa, ca, sb, cb = _sin_cos(xi)
        # Built column by column ([rho1, rho2, n], each (3, k)), then moved to (k, row, column).
        columns = np.array(
            [[sa * cb, ca, sa * sb], [sb, self._zero, -cb], [-ca * cb, sa, -ca * sb]]
        )
        frames = columns.transpose(2, 1, 0)
        return frames if self._rotation is None else self._rotation @ frames

    def metric(self, xi: np.ndarray) -> np.ndarray:
        """``(R, R cos a)``."""
        return np.array([self.radius, self.radius * np.cos(xi[:, 0])]).T

    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """``(0, -R sin(a) a_dot)``."""
        return np.array([self._zero, -self.radius * np.sin(xi[:, 0]) * xi_dot[:, 0]]).T

    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """``I / R`` (constant)."""
        return self._curvature

    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero."""
        return self._zeros

    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """``(0, -tan(a) / R)``."""
        return np.array([self._zero, -np.tan(xi[:, 0]) / self.radius]).T

    def coordinates_of_normal(self, normal: np.ndarray) -> np.ndarray:
        """Invert the Gauss map of unit normals (k, 3), as ``SphereSurface`` does."""
        if self._rotation is not None:
            normal = matvec(self._rotation.transpose(0, 2, 1), normal)
        a = np.arcsin(np.clip(normal[:, 1], -1.0, 1.0))
        b = np.arctan2(-normal[:, 2], -normal[:, 0])
        return np.array([a, b]).T

    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Radial projections, as :meth:`SphereSurface.closest_point`."""
        distance_to_centre = np.sqrt(np.einsum('ki,ki->k', p_in_body, p_in_body))
        if not np.all(distance_to_centre > 0.0):
            raise ValueError("SphereStack.closest_point: a point is its sphere's centre")
        xi = self.coordinates_of_normal(p_in_body / distance_to_centre[:, None])
        return xi, distance_to_centre - self.radius


class FlatStack(SurfaceStack):
    """Planes as in :class:`FlatSurface`: ``c = origin + u e1 + v e2``, M = I, K = 0, T = 0."""

    flat = True

    def __init__(self, planes: Sequence[FlatSurface]) -> None:
        self.origin = np.array([plane.origin for plane in planes])
        self._frame = read_only(np.array([plane.axes for plane in planes]))
        k = len(planes)
        self._ones = read_only(np.ones((k, 2)))
        self._zeros_2 = read_only(np.zeros((k, 2)))
        self._zeros_22 = read_only(np.zeros((k, 2, 2)))

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """Return the constant ``[e1, e2, n]`` of each plane."""
        return self._frame

    def metric(self, xi: np.ndarray) -> np.ndarray:
        """``(1, 1)``."""
        return self._ones

    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero."""
        return self._zeros_2

    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """Zero."""
        return self._zeros_22

    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Zero."""
        return self._zeros_22

    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """Zero."""
        return self._zeros_2

    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orthogonal projections, as :meth:`FlatSurface.closest_point`."""
        # [e1, e2, n]^T (p - origin) per plane: in-plane coordinates, then the distance.
        local = ((p_in_body - self.origin)[:, None, :] @ self._frame)[:, 0, :]
        return local[:, :2], local[:, 2]


class SurfaceList(SurfaceStack):
    """Any surfaces, evaluated one by one through the :class:`Surface` interface."""

    def __init__(self, surfaces: Sequence[Surface]) -> None:
        self.surfaces = [geometry_of(surface) for surface in surfaces]

    def _each(self, method: str, *args: np.ndarray) -> np.ndarray:
        return np.array(
            [
                getattr(surface, method)(*(x[j] for x in args))
                for j, surface in enumerate(self.surfaces)
            ]
        )

    def frame(self, xi: np.ndarray) -> np.ndarray:
        """Each surface's :meth:`Surface.frame`."""
        return self._each('frame', xi)

    def metric(self, xi: np.ndarray) -> np.ndarray:
        """Diagonals of each surface's :meth:`Surface.metric`."""
        return np.diagonal(self._each('metric', xi), axis1=1, axis2=2).copy()

    def metric_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Diagonals of each surface's :meth:`Surface.metric_rate`."""
        return np.diagonal(self._each('metric_rate', xi, xi_dot), axis1=1, axis2=2).copy()

    def curvature(self, xi: np.ndarray) -> np.ndarray:
        """Each surface's :meth:`Surface.curvature`."""
        return self._each('curvature', xi)

    def curvature_rate(self, xi: np.ndarray, xi_dot: np.ndarray) -> np.ndarray:
        """Each surface's :meth:`Surface.curvature_rate`."""
        return self._each('curvature_rate', xi, xi_dot)

    def torsion(self, xi: np.ndarray) -> np.ndarray:
        """Each surface's :meth:`Surface.torsion`."""
        return self._each('torsion', xi)

    def closest_point(self, p_in_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each surface's :meth:`Surface.closest_point`."""
        results = [
            surface.closest_point(p) for surface, p in zip(self.surfaces, p_in_body, strict=True)
        ]
        return np.array([xi for xi, _ in results]), np.array([distance for _, distance in results])


def stack_surfaces(surfaces: Sequence[Surface]) -> SurfaceStack:
    """Stack ``surfaces`` for batched evaluation.

    Closed forms when all are spheres or all planes (:class:`SphereStack`,
    :class:`FlatStack`), otherwise one by one (:class:`SurfaceList`).
    """
    kinds = {type(surface) for surface in surfaces}
    if kinds == {SphereSurface}:
        return SphereStack(surfaces)
    if kinds == {FlatSurface}:
        return FlatStack(surfaces)
    return SurfaceList(surfaces)
