"""The example four-finger hand (config/four_finger_hand.urdf) is what its header says.

Read with Pinocchio's own URDF and collision parsers, not with the package's model: 16
revolute joints by name, positive masses and inertias, effort limits, one collision sphere
per fingertip centred on the tip frame, and at the header's grasp configuration the four
tips touch a 50 mm box (or a 25 mm-radius sphere) centred 0.0752 m above the palm, each
tip's z axis pointing at the object.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

URDF = Path(__file__).resolve().parent.parent / 'config' / 'four_finger_hand.urdf'
FINGERS = ('finger1', 'finger2', 'finger3', 'finger4')
SIDES = {'finger1': (-1, 0), 'finger2': (1, 0), 'finger3': (0, -1), 'finger4': (0, 1)}
TIP_RADIUS = 0.012
HALF_EDGE = 0.025
OBJECT_HEIGHT = 0.0752
GRASP = (0.0, 0.3, 0.6, np.pi / 2 - 0.9)


@pytest.fixture(scope='module')
def hand():
    model = pin.buildModelFromUrdf(str(URDF))
    geometry = pin.buildGeomFromUrdf(model, str(URDF), pin.GeometryType.COLLISION)
    return model, geometry


def grasp_configuration(model) -> np.ndarray:
    q = np.zeros(model.nq)
    for finger in FINGERS:
        for k, value in enumerate(GRASP):
            joint = model.getJointId(f'{finger}_joint{k + 1}')
            q[model.idx_qs[joint]] = value
    return q


def test_sixteen_revolute_joints_with_positive_masses_and_limits(hand):
    model, _ = hand
    names = [model.names[j] for j in range(1, model.njoints)]
    assert sorted(names) == sorted(f'{f}_joint{k}' for f in FINGERS for k in range(1, 5))
    assert model.nq == model.nv == 16
    assert np.all(model.effortLimit > 0)
    assert np.all(model.lowerPositionLimit < model.upperPositionLimit)
    for inertia in model.inertias[1:]:
        assert inertia.mass > 0
        assert np.all(np.linalg.eigvalsh(inertia.inertia) > 0)
    q = grasp_configuration(model)
    assert np.all(q > model.lowerPositionLimit) and np.all(q < model.upperPositionLimit)
    data = model.createData()
    M_h = pin.crba(model, data, q)
    M_h = np.triu(M_h) + np.triu(M_h, 1).T
    assert np.all(np.linalg.eigvalsh(M_h) > 0)


def test_each_fingertip_is_a_collision_sphere_centred_on_its_tip_frame(hand):
    model, geometry = hand
    data = model.createData()
    geometry_data = pin.GeometryData(geometry)
    q = grasp_configuration(model)
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, geometry, geometry_data, q)
    spheres = [
        (g, geometry_data.oMg[i])
        for i, g in enumerate(geometry.geometryObjects)
        if g.geometry.__class__.__name__ == 'Sphere'
    ]
    assert len(spheres) == len(FINGERS)
    for finger in FINGERS:
        tip = data.oMf[model.getFrameId(f'{finger}_tip')].translation
        (radius,) = [
            g.geometry.radius for g, placed in spheres if np.allclose(placed.translation, tip)
        ]
        assert radius == pytest.approx(TIP_RADIUS)


@pytest.mark.parametrize('finger', FINGERS)
def test_at_the_grasp_configuration_each_tip_touches_the_object_face_centre(hand, finger):
    model, _ = hand
    data = model.createData()
    pin.framesForwardKinematics(model, data, grasp_configuration(model))
    placement = data.oMf[model.getFrameId(f'{finger}_tip')]
    outward = np.array([*SIDES[finger], 0.0])  # the face's outward normal, palm frame
    centre = np.array([0.0, 0.0, OBJECT_HEIGHT])
    # Box face: the sphere centre lies one radius off the face, level with the face centre.
    gap = (placement.translation - centre) @ outward - HALF_EDGE - TIP_RADIUS
    assert abs(gap) < 1e-4
    lateral = placement.translation - centre - (placement.translation - centre) @ outward * outward
    assert np.linalg.norm(lateral) < 1e-4
    # Sphere of radius HALF_EDGE at the same centre: touching as well.
    assert np.linalg.norm(placement.translation - centre) == pytest.approx(
        HALF_EDGE + TIP_RADIUS, abs=1e-4
    )
    # The tip's z axis (out of the tip) points into the face.
    np.testing.assert_allclose(placement.rotation[:, 2], -outward, atol=1e-9)
