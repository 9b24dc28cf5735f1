"""Object reference motions for the nominal controller: the paper's r(t) and a planner topic.

A reference is sampled once per tick as a :class:`ReferenceSample`: the desired object pose,
velocity and acceleration feed-forward in palm-frame ZYX Euler coordinates
``r = (x, y, z, roll, pitch, yaw)`` (see :mod:`grasp_safety_filter.control.pose_error`),
convertible to and from pose / twist / acceleration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Protocol

import numpy as np

from grasp_safety_filter.control.filter_rows import all_finite
from grasp_safety_filter.control.pose_error import (
    acceleration_from_euler,
    euler_accelerations_from_acceleration,
    euler_from_matrix,
    euler_rates_from_twist,
    matrix_from_euler,
    twist_from_euler,
)
from grasp_safety_filter.model.compiled import kernel

#: The paper's reference amplitude (Section IV): 0.25 m along palm z, 2 rad of yaw.
PAPER_AMPLITUDE: tuple[float, ...] = (0.0, 0.0, 0.25, 0.0, 0.0, 2.0)
#: The paper's reference angular frequency, rad/s (``cos t``).
PAPER_FREQUENCY: float = 1.0


def _all_finite(values: np.ndarray) -> bool:
    """Whether every entry of a contiguous array is finite (compiled: no numpy call chain)."""
    return all_finite(values.reshape(-1), _NO_VALUES)


_NO_VALUES = np.zeros(0)


def _vector(name: str, value: np.ndarray | None, size: int) -> np.ndarray:
    if value is None:
        return np.zeros(size)
    array = np.array(value, dtype=float)
    if array.shape != (size,) or not _all_finite(array):
        raise ValueError(f'{name}: expected {size} finite numbers, got {value!r}')
    array.flags.writeable = False
    return array


def _rotation(name: str, value: np.ndarray) -> np.ndarray:
    R = np.array(value, dtype=float)
    if R.shape != (3, 3) or not _all_finite(R):
        raise ValueError(f'{name}: expected a finite 3x3 rotation matrix, got {value!r}')
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0.0:
        raise ValueError(f'{name}: expected a rotation matrix (R^T R = I, det R = +1), got {R!r}')
    R.flags.writeable = False
    return R


@dataclass(frozen=True)
class Pose:
    """An object pose in the palm frame.

    Attributes:
        p_in_palm: Object centre of mass, shape (3,), m.
        R_to_palm: Object orientation ``R_object_to_palm``, shape (3, 3).

    """

    p_in_palm: np.ndarray
    R_to_palm: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, 'p_in_palm', _vector('Pose.p_in_palm', self.p_in_palm, 3))
        object.__setattr__(self, 'R_to_palm', _rotation('Pose.R_to_palm', self.R_to_palm))

    @property
    def euler(self) -> np.ndarray:
        """Euler coordinates ``(x, y, z, roll, pitch, yaw)``, shape (6,), m and rad."""
        return np.concatenate((self.p_in_palm, euler_from_matrix(self.R_to_palm)))


@dataclass(frozen=True)
class ReferenceSample:
    """Desired object motion at one instant, in palm-frame ZYX Euler coordinates.

    Attributes:
        r: Pose ``(x, y, z, roll, pitch, yaw)``, shape (6,), m and rad. The angles need not
            be in their principal range (the paper's yaw reaches -4 rad).
        r_dot: Its rate, shape (6,), m/s and rad/s.
        r_ddot: Its second derivative (acceleration feed-forward), shape (6,).
        stale: True when the source could not provide a fresh sample and holds its last
            pose with zero feed-forward (see :class:`TopicReference`).

    """

    r: np.ndarray
    r_dot: np.ndarray = field(default_factory=lambda: np.zeros(6))
    r_ddot: np.ndarray = field(default_factory=lambda: np.zeros(6))
    stale: bool = False

    def __post_init__(self) -> None:
        for name in ('r', 'r_dot', 'r_ddot'):
            value = _vector(f'ReferenceSample.{name}', getattr(self, name), 6)
            object.__setattr__(self, name, value)

    @classmethod
    def from_pose(
        cls,
        pose: Pose,
        twist: np.ndarray | None = None,
        acceleration: np.ndarray | None = None,
        stale: bool = False,
    ) -> ReferenceSample:
        """Build a sample from a pose, twist ``(v, w)`` and acceleration ``(a, alpha)``.

        Twist and acceleration are in palm coordinates (the object's centre-of-mass
        velocity and acceleration, its angular velocity and acceleration); None means zero.
        They are converted with ``r_dot = P^-1 x_dot`` and
        ``r_ddot = P^-1 (x_ddot - P_dot r_dot)``.
        """
        twist = _vector('ReferenceSample.from_pose twist', twist, 6)
        acceleration = _vector('ReferenceSample.from_pose acceleration', acceleration, 6)
        r = pose.euler
        r_dot = euler_rates_from_twist(r[3:], twist)
        r_ddot = euler_accelerations_from_acceleration(r[3:], r_dot, acceleration)
        return cls(r=r, r_dot=r_dot, r_ddot=r_ddot, stale=stale)

    @classmethod
    def _of_checked(cls, r: np.ndarray, r_dot: np.ndarray, r_ddot: np.ndarray) -> ReferenceSample:
        """Wrap finite read-only (6,) float arrays as they are (what the checks would make)."""
        sample = object.__new__(cls)
        object.__setattr__(sample, 'r', r)
        object.__setattr__(sample, 'r_dot', r_dot)
        object.__setattr__(sample, 'r_ddot', r_ddot)
        object.__setattr__(sample, 'stale', False)
        return sample

    @property
    def pose(self) -> Pose:
        """The desired pose."""
        return Pose(self.r[:3], self.R_to_palm)

    @property
    def p_in_palm(self) -> np.ndarray:
        """Desired object centre of mass in the palm frame, shape (3,), m (a read-only view)."""
        return self.r[:3]

    @property
    def R_to_palm(self) -> np.ndarray:
        """Desired orientation ``R_object_to_palm``, shape (3, 3): that of :attr:`pose`."""
        return matrix_from_euler(self.r[3:])

    @property
    def twist(self) -> np.ndarray:
        """Desired twist ``(v, w) = P(phi) r_dot`` in palm coordinates, shape (6,)."""
        return twist_from_euler(self.r[3:], self.r_dot)

    @property
    def acceleration(self) -> np.ndarray:
        """Desired ``(a, alpha) = P r_ddot + P_dot r_dot`` in palm coordinates, shape (6,)."""
        return acceleration_from_euler(self.r[3:], self.r_dot, self.r_ddot)

    def held(self) -> ReferenceSample:
        """Return the same pose with zero velocity and acceleration feed-forward, marked stale."""
        return ReferenceSample(r=self.r, stale=True)


class ReferenceSource(Protocol):
    """Anything that yields a reference sample at time t (s)."""

    def sample(self, t: float) -> ReferenceSample:
        """Return the reference at time ``t``, s."""
        ...


class PaperReference:
    """The paper's reference (Section IV), relative to the initial object pose.

        r(t)      = r0 + A ⊙ (cos(w (t - t0)) - 1)
        r_dot(t)  = -w A ⊙ sin(w (t - t0))
        r_ddot(t) = -w² A ⊙ cos(w (t - t0))

    with r0 the Euler coordinates of the initial pose, so the reference starts there at rest
    (r(t0) = r0, r_dot(t0) = 0). The default amplitude ``A = (0, 0, 0.25, 0, 0, 2)`` moves the
    object 0.25 m along palm z (to z0 - 0.5 m at w t = pi) and turns it about the palm Z axis
    through its centre of mass (yaw down to yaw0 - 4 rad).

    Args:
        initial_pose: Object pose at ``t0``.
        amplitude: A, shape (6,): m for x, y, z; rad for roll, pitch, yaw.
        frequency: Angular frequency w, rad/s (the paper's ``cos t``: w = 1).
        t0: Start time, s.

    """

    def __init__(
        self,
        initial_pose: Pose,
        amplitude: tuple[float, ...] | np.ndarray = PAPER_AMPLITUDE,
        frequency: float = PAPER_FREQUENCY,
        t0: float = 0.0,
    ) -> None:
        self.initial_pose = initial_pose
        self.amplitude = _vector('PaperReference amplitude', amplitude, 6)
        if not (math.isfinite(frequency) and frequency >= 0.0):
            raise ValueError(f'PaperReference frequency: expected >= 0 rad/s, got {frequency!r}')
        if not math.isfinite(t0):
            raise ValueError(f'PaperReference t0: expected a finite time, got {t0!r}')
        self.frequency = float(frequency)
        self.t0 = float(t0)
        self._r0 = initial_pose.euler

    def sample(self, t: float) -> ReferenceSample:
        """Return the reference at time ``t``, s (never stale)."""
        motion = _paper_motion(self._r0, self.amplitude, self.frequency, self.t0, float(t))
        if not _all_finite(motion):
            # The checking constructor names the entry that is not finite.
            return ReferenceSample(r=motion[0], r_dot=motion[1], r_ddot=motion[2])
        motion.flags.writeable = False
        return ReferenceSample._of_checked(motion[0], motion[1], motion[2])


@kernel
def _paper_motion(
    r0: np.ndarray, amplitude: np.ndarray, frequency: float, t0: float, t: float
) -> np.ndarray:
    """Rows ``r, r_dot, r_ddot`` of :class:`PaperReference` at time t, shape (3, 6)."""
    phase = frequency * (t - t0)
    w = frequency
    motion = np.empty((3, 6))
    motion[0] = r0 + amplitude * (math.cos(phase) - 1.0)
    motion[1] = -w * amplitude * math.sin(phase)
    motion[2] = -w * w * amplitude * math.cos(phase)
    return motion


class TopicReference:
    """The latest reference sample received from a planner, with a staleness timeout.

    :meth:`update` stores a sample with its stamp (the message's header stamp, on the same
    clock as the ``t`` passed to :meth:`sample`). While ``t - stamp <= timeout`` the stored
    sample is returned as received (no extrapolation). Once it is older, and before the first
    sample arrives, :meth:`sample` returns a *held* reference: the last pose (initially
    ``initial_pose``) with zero velocity and acceleration feed-forward and ``stale=True``.
    Holding the pose keeps the controller regulating the object where the planner last put
    it, instead of integrating a feed-forward that nobody is updating; the flag lets the
    caller report the condition (diagnostics, bag).

    Args:
        initial_pose: Pose held until the first sample arrives (the object's initial pose).
        timeout: Maximum sample age, s (> 0).

    """

    def __init__(self, initial_pose: Pose, timeout: float) -> None:
        if not (math.isfinite(timeout) and timeout > 0.0):
            raise ValueError(f'TopicReference timeout: expected > 0 s, got {timeout!r}')
        self.timeout = float(timeout)
        self._latest = ReferenceSample(r=initial_pose.euler)
        self._stamp: float | None = None

    @property
    def stamp(self) -> float | None:
        """Stamp of the latest sample, s (None before the first one)."""
        return self._stamp

    def update(self, sample: ReferenceSample, stamp: float) -> None:
        """Store a planner sample stamped ``stamp``, s (replaces the previous one)."""
        if not math.isfinite(stamp):
            raise ValueError(f'TopicReference.update stamp: expected a finite time, got {stamp!r}')
        self._latest = sample
        self._stamp = float(stamp)

    def age(self, t: float) -> float:
        """Age of the latest sample at time ``t``, s (inf before the first one)."""
        return math.inf if self._stamp is None else t - self._stamp

    def is_stale(self, t: float) -> bool:
        """Whether the reference at time ``t`` is held (no sample, or older than timeout)."""
        return self.age(t) > self.timeout

    def sample(self, t: float) -> ReferenceSample:
        """Return the latest sample if fresh at ``t``, else the held last pose (``stale``)."""
        if self.is_stale(t):
            return self._latest.held()
        return self._latest
