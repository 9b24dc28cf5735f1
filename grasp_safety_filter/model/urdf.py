"""Reading a hand's URDF: the file, its XML and the physics Pinocchio takes on trust.

Pinocchio's URDF parser (urdfdom) answers a missing robot, a half-written file or a
non-numeric mass with ``"does not contain a valid URDF model"`` (or loads a mass of 0), and
accepts negative masses and inertias that are not positive definite, which later make
``M_h`` singular or indefinite deep in the filter. :func:`check_urdf_file` reads the file
first, with Python's XML parser, and refuses each of these with a message naming the file,
the element (link, joint) and the value.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from grasp_safety_filter.errors import ConfigError

#: The parameter that names the URDF (in every message).
URDF_PARAMETER = 'model.urdf_file'

#: The six attributes of an ``<inertia>`` element.
INERTIA_ATTRIBUTES = ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz')

#: Joint types that need a ``<limit>`` element (with ``effort`` and ``velocity``).
LIMITED_JOINT_TYPES = ('revolute', 'prismatic')


class HandModelError(ConfigError):
    """The URDF does not describe the hand the configuration expects."""


def check_urdf_file(path: Path) -> ElementTree.Element:
    """Read a URDF and check what the hand model relies on; return its ``<robot>`` element.

    Checks: the file exists and is readable, is well-formed XML with a ``<robot>`` root and
    at least one ``<link>``; every ``<origin>`` and ``<axis>`` vector is three numbers; every
    revolute or prismatic joint has a ``<limit>`` with numeric ``lower``, ``upper``,
    ``effort`` and ``velocity``; every ``<inertial>`` has a finite mass > 0 and a symmetric
    positive definite inertia.

    Raises:
        HandModelError: Naming the file and the link or joint, what was expected and what
            was received.
    """
    where = f"{URDF_PARAMETER}: '{path}'"
    if not path.is_file():
        raise HandModelError(f'{URDF_PARAMETER}: no such file {str(path)!r}')
    try:
        text = path.read_bytes()
    except OSError as error:
        raise HandModelError(f'{where}: cannot read it: {error.strerror}') from None
    try:
        robot = ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        raise HandModelError(f'{where}: expected well-formed XML, got an error: {error}') from None
    if robot.tag != 'robot':
        raise HandModelError(f'{where}: expected a <robot> root element, got <{robot.tag}>')
    links = robot.findall('link')
    if not links:
        raise HandModelError(f'{where}: expected at least one <link> in <robot>, got none')
    for element in (*links, *robot.findall('joint')):
        _check_vectors(element, f"{where}: {element.tag} '{element.get('name')}'")
    for joint in robot.findall('joint'):
        _check_joint(joint, where)
    for link in links:
        inertial = link.find('inertial')
        if inertial is not None:
            _check_inertial(inertial, f"{where}: link '{link.get('name')}'")
    return robot


def _number(
    element: ElementTree.Element, attribute: str, where: str, default: str | None
) -> float:
    """Return ``element``'s numeric attribute (``default`` when absent, an error if None)."""
    text = element.get(attribute, default)
    if text is None:
        raise HandModelError(
            f'{where}: expected a {attribute}="..." attribute in <{element.tag}>, got none'
        )
    try:
        value = float(text)
    except ValueError:
        raise HandModelError(
            f'{where}: expected a number in <{element.tag} {attribute}>, got {text!r}'
        ) from None
    if not math.isfinite(value):
        raise HandModelError(
            f'{where}: expected a finite number in <{element.tag} {attribute}>, got {text!r}'
        )
    return value


def _check_vectors(element: ElementTree.Element, where: str) -> None:
    """Every ``<origin xyz rpy>`` and ``<axis xyz>`` under ``element``: three finite numbers."""
    for child in element.iter():
        if child.tag not in ('origin', 'axis'):
            continue
        for attribute in ('xyz', 'rpy'):
            text = child.get(attribute)
            if text is None:
                continue
            try:
                values = [float(part) for part in text.split()]
            except ValueError:
                values = []
            if len(values) != 3 or not all(math.isfinite(value) for value in values):
                raise HandModelError(
                    f'{where}: expected three numbers in <{child.tag} {attribute}>, got {text!r}'
                )


def _check_joint(joint: ElementTree.Element, where: str) -> None:
    if joint.get('type') not in LIMITED_JOINT_TYPES:
        return
    where = f"{where}: joint '{joint.get('name')}'"
    limit = joint.find('limit')
    if limit is None:
        raise HandModelError(
            f'{where}: expected a <limit> element (a {joint.get("type")} joint), got none'
        )
    for attribute, default in (('lower', '0'), ('upper', '0'), ('effort', None)):
        _number(limit, attribute, where, default)
    _number(limit, 'velocity', where, None)


def _check_inertial(inertial: ElementTree.Element, where: str) -> None:
    mass_element = inertial.find('mass')
    if mass_element is None:
        raise HandModelError(f'{where}: expected a <mass> in its <inertial>, got none')
    mass = _number(mass_element, 'value', where, None)
    if not mass > 0.0:
        raise HandModelError(f'{where}: expected a mass > 0 kg, got {mass:g}')
    inertia_element = inertial.find('inertia')
    if inertia_element is None:
        raise HandModelError(f'{where}: expected an <inertia> in its <inertial>, got none')
    ixx, ixy, ixz, iyy, iyz, izz = (
        _number(inertia_element, attribute, where, None) for attribute in INERTIA_ATTRIBUTES
    )
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    eigenvalues = np.linalg.eigvalsh(inertia)
    if not eigenvalues.min() > 0.0:
        raise HandModelError(
            f'{where}: expected a positive definite inertia, got ixx={ixx:g}, ixy={ixy:g}, '
            f'ixz={ixz:g}, iyy={iyy:g}, iyz={iyz:g}, izz={izz:g} (eigenvalues '
            f'{", ".join(f"{value:.3g}" for value in eigenvalues)} kg m^2)'
        )
