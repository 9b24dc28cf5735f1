"""Grasp constraint margins at one instant: the five families, their values and events.

Five families are watched, each with a margin ``h`` in its own units (``h < 0``: violated):

- ``fingertip_workspace``: per contact, ``(a - a_min, a_max - a, b - b_min, b_max - b)``, rad,
  against the contact's own box.
  The workspace is the open box ``a_min < a < a_max, b_min < b < b_max``, so ``h <= 0`` is
  a violation (the contact point has left the fingertip surface's parameterised patch).
- ``joint_limits``: per joint, ``(q - q_min, q_max - q)``, rad; ``h < 0`` is a violation.
- ``slip``: per contact, the friction margin ``mu_i - beta_i`` (the contact's own mu) with
  ``beta_i = ||f_t,i|| / f_n,i`` (``beta_i = inf`` when ``f_n,i <= 0``); ``h < 0`` is a
  violation. A soft finger (torsional friction ``mu_t,i``, m) also slips by spinning:
  its margin is ``mu_i - max(beta_i, mu_i |tau_i| / (mu_t,i f_n,i))``, negative exactly
  when ``||f_t,i|| > mu_i f_n,i`` or ``|tau_i| > mu_t,i f_n,i`` (``tau_i``: its torsion
  about the normal, N·m).
- ``separation``: per contact, the normal force ``f_n,i``, N; ``f_n,i <= 0`` is a violation.
- ``object_face``: per contact on a box face ``|u| <= h_u, |v| <= h_v``, how far the contact
  point is inside the face's edges, ``min(h_u - |u|, h_v - |v|)``, m; ``h < 0`` is a
  violation (the contact point has rolled off its face). ``inf`` on a sphere object (no
  edge), NaN where the object coordinates or the faces are unknown (flags nothing).

All margins of one instant live in one flat array, family after family (workspace (n, 4),
joints (m, 2), slip (n,), separation (n,), object face (n,), each row-major); the
per-family arrays are views of it. Violations, events and the run's record are evaluated
on that array with one numpy call per quantity, whatever the number of contacts and joints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

FINGERTIP_WORKSPACE = 'fingertip_workspace'
JOINT_LIMITS = 'joint_limits'
SLIP = 'slip'
SEPARATION = 'separation'
OBJECT_FACE = 'object_face'
FAMILIES: tuple[str, ...] = (FINGERTIP_WORKSPACE, JOINT_LIMITS, SLIP, SEPARATION, OBJECT_FACE)
"""Constraint families, in the order the run summary lists them."""

WORKSPACE_SIDES: tuple[str, ...] = ('a_min', 'a_max', 'b_min', 'b_max')
JOINT_SIDES: tuple[str, ...] = ('lower', 'upper')


@dataclass(frozen=True)
class Event:
    """One constraint violated at one instant.

    Attributes:
        t: Time, s.
        family: One of :data:`FAMILIES`.
        index: Contact index (workspace, slip, separation, object face) or joint index
            (joint limits).
        name: The contact's or joint's name.
        side: Which bound: ``"a_min"``, ``"a_max"``, ``"b_min"``, ``"b_max"``, ``"lower"``,
            ``"upper"``; ``""`` for slip, separation and object face.
        margin: The violated margin (rad, rad, 1, N, m for the five families; <= 0).

    """

    t: float
    family: str
    index: int
    name: str
    side: str
    margin: float


@dataclass(frozen=True, eq=False)
class ConstraintMargins:
    """All constraint margins at one instant (negative = violated).

    Attributes:
        t: Time, s.
        fingertip_workspace: Shape (n, 4): ``a - a_min, a_max - a, b - b_min, b_max - b``, rad.
        joint_limits: Shape (m, 2): ``q - q_min, q_max - q``, rad.
        required_friction: ``beta_i``, shape (n,) (``inf`` where ``f_n,i <= 0``).
        friction: ``mu_i - beta_i``, shape (n,) (soft fingers: with their torsion, see the
            module docstring).
        normal_force: ``f_n,i``, shape (n,), N.
        object_face: ``min(h_u - |u|, h_v - |v|)`` per contact, shape (n,), m (NaN where
            unknown).
        values: Every margin, family after family in :data:`FAMILIES` order (the five
            arrays above but ``required_friction``, flattened), shape (7n + 2m,).
        violated_mask: ``values`` violated (``<= 0`` for workspace and separation, ``< 0``
            for the others; NaN: not violated), shape (7n + 2m,).

    """

    t: float
    fingertip_workspace: np.ndarray
    joint_limits: np.ndarray
    required_friction: np.ndarray
    friction: np.ndarray
    normal_force: np.ndarray
    object_face: np.ndarray
    values: np.ndarray = field(repr=False)
    violated_mask: np.ndarray = field(repr=False)

    @property
    def family_starts(self) -> np.ndarray:
        """Index in :attr:`values` where each family's margins start, shape (5,)."""
        sizes = (
            self.fingertip_workspace.size,
            self.joint_limits.size,
            self.friction.size,
            self.normal_force.size,
        )
        return np.cumsum((0, *sizes))

    def by_family(self) -> dict[str, np.ndarray]:
        """Return the margins of each family, in :data:`FAMILIES` order (slip: mu_i - beta_i)."""
        return {
            FINGERTIP_WORKSPACE: self.fingertip_workspace,
            JOINT_LIMITS: self.joint_limits,
            SLIP: self.friction,
            SEPARATION: self.normal_force,
            OBJECT_FACE: self.object_face,
        }

    def violated(self) -> dict[str, np.ndarray]:
        """Boolean violation masks per family, shaped like the margins."""
        starts = self.family_starts
        return {
            family: self.violated_mask[start : start + values.size].reshape(values.shape)
            for (family, values), start in zip(self.by_family().items(), starts, strict=True)
        }


def closed_mask(n_workspace: int, n_joint: int, n_contacts: int) -> np.ndarray:
    """Entries of the flat margins whose constraint is violated at 0 (workspace, separation)."""
    return np.concatenate(
        (
            np.ones(n_workspace, dtype=bool),
            np.zeros(n_joint + n_contacts, dtype=bool),
            np.ones(n_contacts, dtype=bool),
            np.zeros(n_contacts, dtype=bool),
        )
    )
