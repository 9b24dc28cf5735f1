"""Random valid grasp states of the paper's hand, for tests: on the contact manifold, rolling."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'

PAPER_MODEL_PARAMETERS = {
    'model.urdf_file': 'hand.urdf',
    'model.joint_names': [f'finger{i}_joint{j}' for i in (1, 2, 3) for j in (1, 2, 3)],
    'model.fingertip_frames': [f'finger{i}_tip' for i in (1, 2, 3)],
    'model.contact_names': ['finger1', 'finger2', 'finger3'],
    'model.fingertip_radius': 0.06,
    'model.object.shape': 'cube',
    'model.object.mass': 0.11,
    'model.object.size': 0.2604,
    'model.contact_faces': ['-x', '+x', '+y'],
    'model.friction_coefficient': 0.9,
    'model.gravity': [0.0, 0.0, -9.81],
    'model.fingertip_workspace.a_min': -np.pi / 2 + 0.15,
    'model.fingertip_workspace.a_max': np.pi / 2 - 0.15,
    'model.fingertip_workspace.b_min': -np.pi,
    'model.fingertip_workspace.b_max': 0.0,
}
Q_PAPER = np.array([3 * np.pi / 4, 0.75, np.pi / 2 - 0.75] * 3)
P_OBJECT_PAPER = np.array([0.0, 0.0, 0.3 * np.cos(0.75)])


def paper_model(**overrides: object) -> GraspModel:
    """Return the paper's hand and cube (model parameters of config/paper_scenario.yaml)."""
    return GraspModel.from_parameters({**PAPER_MODEL_PARAMETERS, **overrides}, CONFIG_DIR)


@dataclass(frozen=True)
class Configuration:
    """Arguments of GraspModel.state (without t)."""

    q: np.ndarray
    dq: np.ndarray
    p_object: np.ndarray
    R_object: np.ndarray
    twist_object: np.ndarray

    def state(self, model: GraspModel, t: float = 0.0) -> GraspState:
        return model.state(t, self.q, self.dq, self.p_object, self.R_object, self.twist_object)


def random_configuration(
    model: GraspModel, rng: np.random.Generator, spread: float = 0.25, speed: float = 0.5
) -> Configuration:
    """Return a grasp near the paper's, rolling.

    The object pose is perturbed, the fingertips projected onto the faces, the object given
    a random twist and the joints the velocity that rolls the fingertips with it.
    """
    while True:
        p_object = P_OBJECT_PAPER + rng.uniform(-0.04, 0.04, 3)
        R_object = pin.exp3(rng.uniform(-spread, spread, 3))
        q_guess = Q_PAPER + rng.uniform(-spread, spread, Q_PAPER.size)
        try:
            q = model.project_to_contact(q_guess, p_object, R_object)
        except ValueError:
            continue
        geometry = model.contact_geometry(q, p_object, R_object)
        a_b = np.array([g.xi_cf for g in geometry])
        # Keep states away from chart singularities (|a| -> pi/2) and inside the joint range.
        if (
            np.any(np.abs(a_b[:, 0]) > 1.2)
            or np.any(a_b[:, 1] > -0.2)
            or np.any(a_b[:, 1] < -np.pi + 0.2)
        ):
            continue
        if np.any(q <= model.joint_lower_limits) or np.any(q >= model.joint_upper_limits):
            continue
        twist = rng.normal(0.0, speed, 6) * np.array([0.3, 0.3, 0.3, 1.0, 1.0, 1.0])
        dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
        return Configuration(q, dq, p_object, R_object, twist)
