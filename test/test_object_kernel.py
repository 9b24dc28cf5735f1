"""The object's compiled dynamic terms against the numpy formulas (model_oracles)."""

from __future__ import annotations

from grasp_states import CONFIG_DIR
from model_oracles import object_terms
import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.rigid_object import RigidObject


def test_the_compiled_terms_are_the_numpy_formulas():
    model, _ = load_initial_grasp(CONFIG_DIR / 'four_finger_box.yaml')
    rng = np.random.default_rng(0)
    bodies = [model.object]
    for _ in range(10):
        X = rng.normal(size=(3, 3))
        bodies.append(RigidObject(rng.uniform(0.01, 3.0), X @ X.T + 0.1 * np.eye(3), -np.ones(3)))
    assert not any(body.isotropic for body in bodies)
    for body in bodies:
        for _ in range(100):
            R = np.ascontiguousarray(pin.exp3(rng.normal(size=3) * rng.uniform(0.0, 3.0)))
            twist = rng.normal(size=6) * 10.0 ** rng.uniform(-3.0, 2.0)
            for ours, theirs in zip(
                body.dynamics(R, twist), object_terms(body, R, twist), strict=True
            ):
                assert not ours.flags.writeable
                scale = max(float(np.abs(theirs).max()), 1e-300)
                np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-13 * scale)


def test_an_isotropic_object_has_constant_terms():
    body = RigidObject(2.0, 0.3 * np.eye(3), np.array([0.0, 0.0, -9.81]))
    assert body.isotropic
    R = np.ascontiguousarray(pin.exp3(np.array([0.3, -1.0, 2.0])))
    M_o, M_o_inverse, bias = body.dynamics(R, np.arange(6.0))
    np.testing.assert_array_equal(M_o, np.diag([2.0, 2.0, 2.0, 0.3, 0.3, 0.3]))
    np.testing.assert_allclose(M_o_inverse @ M_o, np.eye(6), atol=1e-15)
    np.testing.assert_array_equal(bias, np.zeros(6))
