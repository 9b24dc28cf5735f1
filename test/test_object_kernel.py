"""An anisotropic object's compiled dynamic terms against RigidObject's methods, to the bit."""

from __future__ import annotations

from grasp_states import CONFIG_DIR
import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.object_kernel import object_dynamics
from grasp_safety_filter.model.rigid_object import RigidObject


def test_the_compiled_terms_are_the_methods_terms():
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
            inertia = (body.inertia_in_body, body.inverse_inertia_in_body)
            M_o, M_o_inverse, bias = object_dynamics(body.mass, inertia, R, twist)
            np.testing.assert_array_equal(M_o, body.inertia_matrix(R))
            np.testing.assert_array_equal(bias, body.bias_wrench(R, twist))
            np.testing.assert_array_equal(M_o_inverse, body.inverse_inertia_matrix(R))
