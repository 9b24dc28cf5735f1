"""Surface geometry: every chart's closed forms against their definitions (finite differences).

The closed forms are the oracle's (oracle_geometry), which the compiled contact kernels are
checked against; the surfaces' descriptions (faces, charts, validation) are the model's.
"""

from __future__ import annotations

import numpy as np
from oracle_geometry import geometry_of
import pytest

from grasp_safety_filter.model.object_shapes import sphere_chart_centred_on
from grasp_safety_filter.model.surfaces import box_face, cube_face, FlatSurface, SphereSurface

EPS = 1e-6

SURFACES = {
    'sphere fingertip R=0.06': (
        SphereSurface(0.06),
        lambda rng: np.array([rng.uniform(-1.3, 1.3), rng.uniform(-3.0, -0.1)]),
    ),
    'sphere object R=0.2': (
        SphereSurface(0.2),
        lambda rng: np.array([rng.uniform(-1.3, 1.3), rng.uniform(-3.0, 3.0)]),
    ),
    'sphere object R=0.025, chart turned to a contact normal': (
        SphereSurface(0.025, sphere_chart_centred_on(np.array([0.3, -0.8, 0.52]))),
        lambda rng: np.array([rng.uniform(-1.3, 1.3), rng.uniform(-3.0, 3.0)]),
    ),
    'cube face -x': (cube_face('-x', 0.2604), lambda rng: rng.uniform(-0.13, 0.13, 2)),
    'box face +y of 0.05 x 0.06 x 0.08': (
        box_face('+y', (0.05, 0.06, 0.08)),
        lambda rng: rng.uniform(-0.02, 0.02, 2),
    ),
    'tilted plane': (
        FlatSurface(
            np.array([0.1, -0.2, 0.3]), np.array([0.6, 0.8, 0.0]), np.array([0.0, 0.0, 1.0])
        ),
        lambda rng: rng.uniform(-1.0, 1.0, 2),
    ),
}


def d(f, xi, k):
    step = np.zeros(2)
    step[k] = EPS
    return (np.asarray(f(xi + step)) - np.asarray(f(xi - step))) / (2 * EPS)


@pytest.fixture(params=list(SURFACES), ids=list(SURFACES))
def surface_samples(request):
    surface, sample = SURFACES[request.param]
    rng = np.random.default_rng(1)
    return geometry_of(surface), [sample(rng) for _ in range(20)]


def test_tangents_are_derivatives_of_the_point(surface_samples):
    surface, samples = surface_samples
    for xi in samples:
        c_a, c_b = d(surface.point, xi, 0), d(surface.point, xi, 1)
        np.testing.assert_allclose(surface.tangents(xi), np.column_stack([c_a, c_b]), atol=1e-8)
        assert abs(c_a @ c_b) < 1e-8  # orthogonal chart (the paper's Assumption 6)


def test_gauss_frame_is_right_handed_with_outward_normal(surface_samples):
    surface, samples = surface_samples
    for xi in samples:
        R = surface.frame(xi)
        c_a, c_b = surface.tangents(xi).T
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        # rho2 = c_b / |c_b| (the paper's eq. 5 has c_a / |c_b|), n = rho1 × rho2.
        np.testing.assert_allclose(R[:, 0], c_a / np.linalg.norm(c_a), atol=1e-12)
        np.testing.assert_allclose(R[:, 1], c_b / np.linalg.norm(c_b), atol=1e-12)
        # Outward: moving along n leaves the surface with positive signed distance.
        xi_back, distance = surface.closest_point(surface.point(xi) + 0.01 * R[:, 2])
        assert distance == pytest.approx(0.01)
        np.testing.assert_allclose(xi_back, xi, atol=1e-9)


def test_metric_curvature_torsion_match_their_definitions(surface_samples):
    surface, samples = surface_samples
    for xi in samples:
        c_a, c_b = surface.tangents(xi).T
        norms = np.array([np.linalg.norm(c_a), np.linalg.norm(c_b)])
        np.testing.assert_allclose(surface.metric(xi), np.diag(norms), atol=1e-12)
        R = surface.frame(xi)
        dn = np.column_stack(
            [d(lambda x: surface.frame(x)[:, 2], xi, k) / norms[k] for k in range(2)]
        )
        np.testing.assert_allclose(surface.curvature(xi), R[:, :2].T @ dn, atol=1e-7)
        drho1 = np.column_stack(
            [d(lambda x: surface.frame(x)[:, 0], xi, k) / norms[k] for k in range(2)]
        )
        np.testing.assert_allclose(surface.torsion(xi), R[:, 1] @ drho1, atol=1e-7)


def test_rates_match_finite_differences(surface_samples):
    surface, samples = surface_samples
    rng = np.random.default_rng(2)
    for xi in samples:
        xi_dot = rng.normal(size=2)

        def along(f, xi=xi, xi_dot=xi_dot):
            return (f(xi + EPS * xi_dot) - f(xi - EPS * xi_dot)) / (2 * EPS)

        np.testing.assert_allclose(surface.frame_rate(xi, xi_dot), along(surface.frame), atol=1e-7)
        np.testing.assert_allclose(
            surface.metric_rate(xi, xi_dot), along(surface.metric), atol=1e-7
        )
        np.testing.assert_allclose(
            surface.curvature_rate(xi, xi_dot), along(surface.curvature), atol=1e-7
        )


def test_sphere_closed_forms_of_the_design_notes():
    R = 0.06
    sphere = geometry_of(SphereSurface(R))
    for a, b in [(0.0, -np.pi / 2), (0.4, -1.0), (-1.1, -2.5)]:
        xi = np.array([a, b])
        np.testing.assert_allclose(sphere.metric(xi), np.diag([R, R * np.cos(a)]))
        np.testing.assert_allclose(sphere.curvature(xi), np.eye(2) / R)
        np.testing.assert_allclose(sphere.torsion(xi), [0.0, -np.tan(a) / R])
        np.testing.assert_allclose(sphere.frame(xi)[:, 2], sphere.point(xi) / R, atol=1e-15)
        np.testing.assert_allclose(
            sphere.coordinates_of_normal(sphere.point(xi) / R), xi, atol=1e-12
        )
    # The tip of the fingertip is (a, b) = (0, -pi/2), on the frame's +z axis.
    np.testing.assert_allclose(
        sphere.point(np.array([0.0, -np.pi / 2])), [0.0, 0.0, R], atol=1e-15
    )


@pytest.mark.parametrize(
    ('make', 'message'),
    [
        (lambda: SphereSurface(0.0), 'radius'),
        (lambda: SphereSurface(float('nan')), 'radius'),
        (
            lambda: FlatSurface(np.zeros(3), np.array([1.0, 0, 0]), np.array([1.0, 0, 0])),
            'orthogonal',
        ),
        (lambda: FlatSurface(np.zeros(3), np.array([2.0, 0, 0]), np.array([0.0, 1, 0])), 'unit'),
        (lambda: cube_face('x', 0.2), 'expected one of'),
        (lambda: cube_face('+x', -1.0), 'edge length'),
    ],
)
def test_invalid_surfaces_are_rejected(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_box_face_is_the_rectangle_of_its_two_in_plane_edges():
    # Face +y of a 0.05 x 0.06 x 0.08 m box: at y = 0.03, chart axes (e1, e2) = (z, x).
    face = geometry_of(box_face('+y', (0.05, 0.06, 0.08)))
    np.testing.assert_allclose(face.origin, [0.0, 0.03, 0.0])
    np.testing.assert_allclose(face.normal, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(face.point(np.array([0.01, 0.02])), [0.02, 0.03, 0.01])
    assert face.outside_distance(np.array([0.039, 0.024])) < 0.0
    assert face.outside_distance(np.array([0.041, 0.0])) == pytest.approx(0.001)
    assert face.outside_distance(np.array([0.0, -0.03])) == pytest.approx(0.005)
    # A cube is the box of three equal edges, face by face.
    for label in ('+x', '-x', '+y', '-y', '+z', '-z'):
        cube, box = cube_face(label, 0.2604), box_face(label, (0.2604,) * 3)
        np.testing.assert_array_equal(cube.origin, box.origin)
        np.testing.assert_array_equal(cube.axes, box.axes)


def test_a_turned_sphere_chart_is_centred_on_its_normal_far_from_its_poles():
    rng = np.random.default_rng(4)
    for _ in range(50):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        R_chart = sphere_chart_centred_on(normal)
        np.testing.assert_allclose(R_chart.T @ R_chart, np.eye(3), atol=1e-12)
        assert np.linalg.det(R_chart) == pytest.approx(1.0)
        sphere = geometry_of(SphereSurface(0.025, R_chart))
        xi = sphere.coordinates_of_normal(normal)
        np.testing.assert_allclose(xi, [0.0, -np.pi / 2], atol=1e-12)
        np.testing.assert_allclose(sphere.point(xi), 0.025 * normal, atol=1e-15)
        # The chart's poles (|c_b| = 0) are the directions +-R_chart e_y: a quarter circle away.
        poles = [sphere.point(np.array([s * np.pi / 2, -np.pi / 2])) / 0.025 for s in (1, -1)]
        for pole in poles:
            assert abs(pole @ normal) < 1e-12
        # The metric there is R I: the chart is as regular as at the fingertip's tip.
        np.testing.assert_allclose(sphere.metric(xi), 0.025 * np.eye(2), atol=1e-15)
