"""MJCF of a grasp model: the hand, its fingertip spheres and the object, for MuJoCo.

The MJCF is generated from our parsed model (the Pinocchio model the grasp model's
:class:`~grasp_safety_filter.model.hand.HandModel` built from the URDF), not by MuJoCo's own
URDF importer, so that both engines use the same numbers exactly:

- one MuJoCo body per Pinocchio joint, nested as Pinocchio's kinematic tree, placed at the
  joint's placement in its parent joint's frame (``model.jointPlacements``), with the joint's
  hinge axis and limits and the body's inertia as Pinocchio holds it, i.e. with the links
  fixed to it merged in (MuJoCo's importer merges fixed links too, but by its own rules and
  with ``discardvisual``/``fusestatic`` settings to get right; here nothing is left to them);
- the URDF's root link is the world: the palm frame P is MuJoCo's world frame (gravity, the
  object pose and twist are in P in both engines);
- per contact, the fingertip sphere (our radius, centred on our fingertip frame, with its
  axes) as the only geoms of the hand: they collide with the object and nothing else;
- the object as a free body whose frame is the object frame O (origin at the centre of mass),
  a box or sphere geom with our mass and inertia (given explicitly: no inertia from geoms);
- one motor per joint in the model's joint order, gear 1, ``ctrlrange`` the URDF effort limit.

Contact and integration parameters are :class:`MjcfOptions` (MuJoCo's defaults unless said).
The contacts keep MuJoCo's default ``margin`` and ``gap`` of 0: a positive margin makes a
contact push from that distance on (the surfaces act inflated by the sum of the margins).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.parameters import flatten_parameters
from grasp_safety_filter.io.plant_schema import (
    MUJOCO_CONES,
    MUJOCO_INTEGRATORS,
    PLANT_PARAMETERS,
)
from grasp_safety_filter.model.grasp_model import GraspModel

#: MuJoCo's friction cones.
CONES = MUJOCO_CONES
#: MuJoCo's integrators (MJCF spelling).
INTEGRATORS = MUJOCO_INTEGRATORS

#: MuJoCo's contact dimensionalities: frictionless, tangential, + torsional, + rolling.
CONDIMS = (1, 3, 4, 6)
#: Prefix of the ``hand_sim_node`` parameters of :class:`MjcfOptions`.
PARAMETER_PREFIX = 'mujoco.'

_SPECS = {spec.name: spec for spec in PLANT_PARAMETERS}


def _default(name: str) -> Any:
    """Return the default of parameter ``mujoco.<name>`` (a tuple for an array)."""
    value = _SPECS[PARAMETER_PREFIX + name].default
    return tuple(value) if isinstance(value, list) else value


#: Name of the object's free body (and of its geom and free joint, with suffixes).
OBJECT_BODY = 'object'


def fingertip_geom_name(contact_name: str) -> str:
    """Name of contact ``contact_name``'s fingertip sphere geom."""
    return f'{contact_name}/fingertip'


class MjcfError(ConfigError):
    """A MuJoCo option or a model that has no MJCF (the message says which and why)."""


@dataclass(frozen=True)
class MjcfOptions:
    """MuJoCo's contact and integration parameters.

    Attributes:
        friction_coefficient: Sliding friction μ of every fingertip–object contact; None:
            each contact's own μ from the grasp model (the filter's and the plant's the same).
        torsional_friction: Torsional friction, m (used with ``condim`` 4 and 6); MuJoCo's
            default 0.005.
        rolling_friction: Rolling friction, m (``condim`` 6); MuJoCo's default 0.0001.
        cone: ``"pyramidal"`` (MuJoCo's default) or ``"elliptic"``.
        condim: Contact dimensionality 1, 3 (MuJoCo's default: normal + tangential), 4 or 6.
        solref: ``(timeconst, dampratio)`` of the contacts, (s, -); MuJoCo's default
            (0.02, 1). A smaller time constant is a stiffer contact (it needs
            ``timestep`` ≤ timeconst / 2).
        solimp: ``(dmin, dmax, width, midpoint, power)``; MuJoCo's default
            (0.9, 0.95, 0.001, 0.5, 2).
        impratio: Ratio of the frictional to the normal constraint impedance; MuJoCo's default
            1. Larger values make friction stiffer (MuJoCo advises it with elliptic cones).
        noslip_iterations: Iterations of MuJoCo's no-slip post-solver; MuJoCo's default 0
            (off). Soft friction creeps under a steady tangential load, at a speed about
            proportional to the load; the no-slip solver removes that creep.
        timestep: MuJoCo's step, s. Not MuJoCo's default 0.002 s: the scenarios' control
            period is 1 ms, which must be a whole number of MuJoCo steps.
        integrator: ``"Euler"`` (MuJoCo's default, semi-implicit), ``"RK4"``, ``"implicit"``
            or ``"implicitfast"``.
        joint_limits: Whether the URDF's joint limits are hard stops in MuJoCo (as on a real
            hand); our rigid simulator has none (the filter keeps the joints in range).
    """

    friction_coefficient: float | None = None
    torsional_friction: float = _default('torsional_friction')
    rolling_friction: float = _default('rolling_friction')
    cone: str = _default('cone')
    condim: int = _default('condim')
    solref: tuple[float, float] = _default('solref')
    solimp: tuple[float, float, float, float, float] = _default('solimp')
    impratio: float = _default('impratio')
    noslip_iterations: int = _default('noslip_iterations')
    timestep: float = _default('timestep')
    integrator: str = _default('integrator')
    joint_limits: bool = _default('joint_limits')

    def __post_init__(self) -> None:
        def positive(name: str, value: float) -> None:
            if not (np.isfinite(value) and value > 0.0):
                raise MjcfError(f'mujoco.{name}: expected a positive number, got {value!r}')

        if self.friction_coefficient is not None:
            positive('friction_coefficient', self.friction_coefficient)
        positive('torsional_friction', self.torsional_friction)
        positive('rolling_friction', self.rolling_friction)
        positive('timestep', self.timestep)
        positive('impratio', self.impratio)
        if not (isinstance(self.noslip_iterations, int) and self.noslip_iterations >= 0):
            raise MjcfError(
                'mujoco.noslip_iterations: expected an integer >= 0, got '
                f'{self.noslip_iterations!r}'
            )
        if self.cone not in CONES:
            raise MjcfError(f'mujoco.cone: expected one of {list(CONES)}, got {self.cone!r}')
        if self.condim not in CONDIMS:
            raise MjcfError(f'mujoco.condim: expected one of {list(CONDIMS)}, got {self.condim!r}')
        if self.integrator not in INTEGRATORS:
            raise MjcfError(
                f'mujoco.integrator: expected one of {list(INTEGRATORS)}, got {self.integrator!r}'
            )
        if len(self.solref) != 2 or not all(np.isfinite(x) and x > 0.0 for x in self.solref):
            raise MjcfError(
                f'mujoco.solref: expected (timeconst > 0, dampratio > 0), got {self.solref!r}'
            )
        dmin, dmax, width, midpoint, power = self.solimp
        if not (0.0 < dmin <= dmax < 1.0 and width > 0.0 and 0.0 < midpoint < 1.0 and power >= 1):
            raise MjcfError(
                'mujoco.solimp: expected 0 < dmin <= dmax < 1, width > 0, 0 < midpoint < 1, '
                f'power >= 1, got {self.solimp!r}'
            )

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> MjcfOptions:
        """Build from ``hand_sim_node``'s ``mujoco.*`` parameters (missing: defaults).

        ``mujoco.friction_coefficient`` 0 stands for None (each contact's model μ).

        Raises:
            ParameterError: A parameter of the wrong type or out of range.
            MjcfError: Values the schema admits and MuJoCo does not (``condim`` 2, ...).
        """
        flat = flatten_parameters(params)
        values: dict[str, Any] = {}
        for f in fields(cls):
            name = PARAMETER_PREFIX + f.name
            value = _SPECS[name].validate(flat[name]) if name in flat else _default(f.name)
            values[f.name] = tuple(value) if isinstance(value, list) else value
        if values['friction_coefficient'] == 0.0:
            values['friction_coefficient'] = None
        return cls(**values)

    def friction(self, model: GraspModel) -> np.ndarray:
        """Return the sliding friction coefficient of each contact MuJoCo uses, shape (n,)."""
        if self.friction_coefficient is None:
            return np.array(model.friction_coefficient, dtype=float).reshape(model.n_contacts)
        return np.full(model.n_contacts, float(self.friction_coefficient))


def _numbers(values: np.ndarray | tuple[float, ...] | list[float]) -> str:
    """Space-separated floats written to round-trip exactly (``repr``)."""
    return ' '.join(repr(float(x)) for x in np.ravel(values))


def _quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    q = pin.Quaternion(np.asarray(R, dtype=float))
    q.normalize()
    return np.array([q.w, q.x, q.y, q.z])


def _hinge_axis(joint: pin.JointModel) -> np.ndarray:
    """Return the revolute joint's axis in its own frame."""
    short = joint.shortname()
    for suffix, axis in (('RX', 0), ('RY', 1), ('RZ', 2)):
        if short.endswith(suffix):
            return np.eye(3)[axis]
    if 'Unaligned' in short:
        return np.asarray(joint.extract().axis, dtype=float)
    raise MjcfError(f'mjcf: joint type {short} has no MuJoCo hinge here (revolute joints only)')


def _inertial(body: ET.Element, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    """``<inertial>`` at ``com`` with the full inertia about the centre of mass."""
    ixx, iyy, izz = inertia[0, 0], inertia[1, 1], inertia[2, 2]
    ixy, ixz, iyz = inertia[0, 1], inertia[0, 2], inertia[1, 2]
    ET.SubElement(
        body,
        'inertial',
        pos=_numbers(com),
        mass=repr(float(mass)),
        fullinertia=_numbers([ixx, iyy, izz, ixy, ixz, iyz]),
    )


def mjcf_from_model(model: GraspModel, options: MjcfOptions | None = None) -> str:
    """Return the MJCF text of ``model`` (see the module docstring).

    Raises:
        MjcfError: The model has no object shape (contacts given explicitly), or a joint
            is not revolute.
    """
    options = options or MjcfOptions()
    shape = model.object_shape
    if shape is None:
        raise MjcfError('mjcf: the grasp model has no object shape (model.object.shape)')
    hand = model.hand
    pin_model = hand.model
    mu = options.friction(model)

    def friction(sliding: float) -> str:
        return _numbers([sliding, options.torsional_friction, options.rolling_friction])

    # MuJoCo gives a contact the larger of its two geoms' coefficients: each fingertip
    # carries its contact's μ, the object the smallest, so every contact gets its own.
    contact_attributes = {
        'condim': str(options.condim),
        'solref': _numbers(options.solref),
        'solimp': _numbers(options.solimp),
    }
    mu_of_contact = dict(zip(model.contact_names, mu, strict=True))

    root = ET.Element('mujoco', model='grasp')
    ET.SubElement(root, 'compiler', angle='radian', inertiafromgeom='false', autolimits='true')
    ET.SubElement(
        root,
        'option',
        timestep=repr(float(options.timestep)),
        integrator=options.integrator,
        cone=options.cone,
        impratio=repr(float(options.impratio)),
        noslip_iterations=str(options.noslip_iterations),
        gravity=_numbers(np.asarray(pin_model.gravity.linear)),
    )
    world = ET.SubElement(root, 'worldbody')

    tips_by_joint: dict[int, list[tuple[str, float, pin.SE3]]] = {}
    for name, tip in zip(model.contact_names, hand.fingertips, strict=True):
        frame = pin_model.frames[tip.frame_id]
        tips_by_joint.setdefault(frame.parentJoint, []).append((name, tip.radius, frame.placement))

    bodies = {0: world}
    lower = pin_model.lowerPositionLimit
    upper = pin_model.upperPositionLimit
    for j in range(1, pin_model.njoints):
        joint = pin_model.joints[j]
        name = pin_model.names[j]
        placement = pin_model.jointPlacements[j]
        body = ET.SubElement(
            bodies[pin_model.parents[j]],
            'body',
            name=name,
            pos=_numbers(placement.translation),
            quat=_numbers(_quaternion_wxyz(placement.rotation)),
        )
        bodies[j] = body
        inertia = pin_model.inertias[j]
        _inertial(body, inertia.mass, np.asarray(inertia.lever), np.asarray(inertia.inertia))
        hinge = {'name': name, 'type': 'hinge', 'axis': _numbers(_hinge_axis(joint))}
        if options.joint_limits:
            k = joint.idx_q
            hinge['range'] = _numbers([lower[k], upper[k]])
        ET.SubElement(body, 'joint', **hinge)
        for contact_name, radius, tip_placement in tips_by_joint.get(j, []):
            ET.SubElement(
                body,
                'geom',
                name=fingertip_geom_name(contact_name),
                type='sphere',
                size=repr(float(radius)),
                pos=_numbers(tip_placement.translation),
                quat=_numbers(_quaternion_wxyz(tip_placement.rotation)),
                contype='1',
                conaffinity='0',
                friction=friction(mu_of_contact[contact_name]),
                **contact_attributes,
            )

    # The object: its frame O at the centre of mass; it collides with the fingertips only.
    obj = ET.SubElement(world, 'body', name=OBJECT_BODY)
    ET.SubElement(obj, 'freejoint', name=f'{OBJECT_BODY}/free')
    rigid = model.object
    _inertial(obj, rigid.mass, np.zeros(3), rigid.inertia_in_body)
    if shape.has_faces:
        geom = {'type': 'box', 'size': _numbers(0.5 * np.asarray(shape.edge_lengths))}
    else:
        geom = {'type': 'sphere', 'size': repr(float(shape.radius))}
    ET.SubElement(
        obj,
        'geom',
        name=f'{OBJECT_BODY}/shape',
        contype='0',
        conaffinity='1',
        friction=friction(float(mu.min())),
        **geom,
        **contact_attributes,
    )

    actuators = ET.SubElement(root, 'actuator')
    for name, limit in zip(hand.joint_names, hand.effort_limits, strict=True):
        ET.SubElement(
            actuators,
            'motor',
            name=name,
            joint=name,
            gear='1',
            ctrlrange=_numbers([-limit, limit]),
        )
    ET.indent(root)
    return ET.tostring(root, encoding='unicode')
