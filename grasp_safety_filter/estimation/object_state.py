"""The grasped object's pose and twist at the hand's joint-state rate.

An object tracker (vision, motion capture) gives the object's pose in the palm frame P at
30–240 Hz, stamped with its capture time, 10–50 ms late, with millimetre noise (DESIGN.md
§9). The hand's joint states come at the control rate. Under rolling without slipping
(DESIGN.md §3) the joints measure the object's twist ``x_o_dot = (v_o, w_o)`` (palm
coordinates) at their own rate,

    G^T x_o_dot = J_h dq,

and the tracker removes the drift of its integral. The estimator combines the two.

**Prediction**, at every ``estimate(t_k, dq_k)``, with ``J_h`` (k×m) and ``G`` (6×k) of the
:class:`~grasp_safety_filter.model.grasp_state.GraspState` observed at the previous
estimate (:meth:`ObjectStateEstimator.observe`)::

    x_k = argmin_x |G^T x - J_h dq_k|                    (least squares: G^T is tall)
    p_k = p_{k-1} + (v_{k-1} + v_k) / 2 · dt
    R_k = exp3((w_{k-1} + w_k) / 2 · dt) R_{k-1}         (palm-frame w multiplies on the left)

with ``dt = t_k - t_{k-1}``. The matrices are one tick old: with ``x`` the exact twist at
``t_k``, ``x_k - x = pinv(G_{k-1}^T) [(J_h,{k-1} - J_h,k) dq_k - (G_{k-1} - G_k)^T x]``, a
difference of each matrix over one tick, so a relative twist error of the order of the
joint rates times ``dt`` (below 5e-4 on the paper's run at 1 kHz). Before any state was
observed, and when ``G`` is numerically singular (condition number above
:data:`MAX_GRASP_MAP_CONDITION`) or the result is not finite, the twist is the newest
tracker sample's (zero without one) and the estimate says so (``twist_source``).

**Correction** by the j-th tracker sample ``(p_z, R_z)`` since the reset, captured at
``t_c``, ``dt_c`` after the previous one's capture::

    p̂, R̂ = the estimate at t_c: the history of past estimates interpolated
             (linearly in p, along log3 in R); beyond its ends, its end extrapolated
             with that end's twist
    dp = p_z - p̂,    dθ = log3(R_z R̂^T)
    K_j = max(1/j, 1 - exp(-dt_c / tau))                 (K = 1 when tau = 0)
    p ← p + K dp,    R ← exp3(K dθ) R                    (the current estimate and the history)

The first sample sets the pose (and the twist, if it carries one). Comparing at the
capture time makes the tracker's latency cost nothing when the prediction is right (the
rotation measured at ``t_c`` and applied at the tick is off by the object's rotation over
the latency: second order). With ``K_j = 1/j`` the first samples are averaged; afterwards an
offset between tracker and prediction decays as ``exp(-(t_c - t_0) / tau)`` over capture
time, at any sample rate. tau trades noise against lag: white tracker noise of std σ per
axis leaves ``σ sqrt(K / (2 - K)) ≈ σ sqrt(dt_c / (2 tau))`` in the estimate, and a motion
the joints do not see (slip, creep) at speed d is followed ``≈ d tau`` behind.

Stamps are integer nanoseconds throughout; seconds appear only in products with rates.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
import math
import operator

import numpy as np
import pinocchio as pin

__all__ = ['ObjectEstimate', 'ObjectEstimateConfig', 'ObjectStateEstimator', 'TrackerSample']

#: Largest condition number of ``G`` whose kinematic twist is used (the paper's grasp: 16).
MAX_GRASP_MAP_CONDITION = 1e6
#: Largest ``|R^T R - I|`` entry of a tracker orientation accepted.
ROTATION_TOLERANCE = 1e-6
KINEMATICS = 'kinematics'
TRACKER = 'tracker'
_NS = 1e-9


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class ObjectEstimateConfig:
    """The estimator's time constants.

    Attributes:
        correction_time: tau, s: time constant of the tracker correction (≥ 0); 0: each
            tracker pose is taken as it is.
        max_age: s (> 0): the estimate is stale when its newest tracker sample was captured
            more than this before the tick.
        history: s (> 0) of past estimates kept to compare a delayed tracker sample with the
            estimate at its capture time (at least the tracker's latency).
    """

    correction_time: float = 0.1
    max_age: float = 0.5
    history: float = 0.25

    def __post_init__(self) -> None:
        for name, positive in (('correction_time', False), ('max_age', True), ('history', True)):
            value = getattr(self, name)
            bound = '> 0' if positive else '>= 0'
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f'{name}: expected a number {bound} (s), got {value!r}')
            if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
                raise ValueError(f'{name}: expected a finite number {bound} (s), got {value!r}')
            object.__setattr__(self, name, float(value))


@dataclass(frozen=True)
class TrackerSample:
    """One pose of the object from the tracker (arrays are copied read-only).

    Attributes:
        stamp_ns: Capture time, integer ns.
        p_object_in_palm: Object centre of mass in P, (3,), m.
        R_object_to_palm: Object orientation, (3, 3), orthonormal.
        twist_object: Object twist ``(v, w)`` in palm coordinates, (6,), (m/s, rad/s), or
            None (``geometry_msgs/PoseStamped`` has none).
    """

    stamp_ns: int
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray | None

    def __post_init__(self) -> None:
        object.__setattr__(self, 'stamp_ns', _stamp('stamp_ns', self.stamp_ns))
        shapes = {'p_object_in_palm': (3,), 'R_object_to_palm': (3, 3), 'twist_object': (6,)}
        for name, shape in shapes.items():
            if (value := getattr(self, name)) is not None or name != 'twist_object':
                array = _readonly(value)
                if array.shape != shape or not np.all(np.isfinite(array)):
                    raise ValueError(f'{name}: expected finite values of shape {shape}')
                object.__setattr__(self, name, array)
        R = self.R_object_to_palm
        if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) < 0.0:
            raise ValueError('R_object_to_palm: expected a rotation matrix (orthonormal, det 1)')


@dataclass(frozen=True)
class ObjectEstimate:
    """The object's state at a tick (read-only arrays).

    Attributes:
        stamp_ns: The tick's stamp, integer ns.
        p_object_in_palm: Object centre of mass in P, (3,), m.
        R_object_to_palm: Object orientation, (3, 3), orthonormal.
        twist_object: Object twist ``(v, w)`` in palm coordinates, (6,), (m/s, rad/s).
        tracker_age: The tick's stamp minus the newest tracker sample's capture stamp, s
            (< 0 when the tracker is ahead of the joint states).
        twist_source: ``'kinematics'`` (from dq and the last observed J_h, G) or
            ``'tracker'`` (the newest sample's twist, or zeros without one).
        stale: ``tracker_age`` exceeds the configuration's ``max_age``.
    """

    stamp_ns: int
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray
    tracker_age: float
    twist_source: str
    stale: bool = False


def _stamp(name: str, value: object) -> int:
    try:
        return operator.index(value)
    except TypeError:
        raise ValueError(f'{name}: expected an integer number of ns, got {value!r}') from None


def _moved(
    p: np.ndarray, R: np.ndarray, twist: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Return the pose ``(p, R)`` moved ``dt`` s with the palm-frame twist held."""
    return p + twist[:3] * dt, pin.exp3(twist[3:] * dt) @ R


class ObjectStateEstimator:
    """Object pose and twist at the joint-state rate (see the module's docstring).

    Call :meth:`add_tracker_sample` as samples arrive, :meth:`estimate` at every joint-state
    tick, then :meth:`observe` with the model terms computed at that estimate.

    Args:
        config: The time constants.
    """

    def __init__(self, config: ObjectEstimateConfig) -> None:
        self.config = config
        self._history_ns = round(config.history * 1e9)
        self._max_age_ns = round(config.max_age * 1e9)
        self.reset()

    def reset(self) -> None:
        """Forget the pose, the samples, the history and the observed model terms."""
        self._stamp_ns: int | None = None  # of the newest estimate
        self._p = np.zeros(3)
        self._R = np.eye(3)
        self._twist = np.zeros(6)
        self._samples = 0
        self._sample_stamp_ns: int | None = None
        self._sample_twist = np.zeros(6)
        self._J_h: np.ndarray | None = None
        self._G: np.ndarray | None = None
        # Past estimates (stamp, p - C, E^T R, twist), C and E the correction accumulated
        # since the reset: an entry's corrected pose is (p + C, E R), so shifting the whole
        # history by a correction only updates C and E.
        self._stamps: list[int] = []
        self._entries: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._C = np.zeros(3)
        self._E = np.eye(3)

    @property
    def has_pose(self) -> bool:
        """A tracker sample has set the pose since the reset."""
        return self._stamp_ns is not None

    def observe(self, state: object) -> None:
        """Keep ``state.J_h`` (k, m) and ``state.G`` (6, k) for the next kinematic twist.

        ``state`` is the :class:`~grasp_safety_filter.model.grasp_state.GraspState` computed
        at the last estimate (only these two terms are read).
        """
        J_h = np.array(state.J_h, dtype=float)
        G = np.array(state.G, dtype=float)
        if G.ndim != 2 or J_h.ndim != 2 or G.shape[0] != 6 or G.shape[1] != J_h.shape[0]:
            raise ValueError(
                f'state: expected J_h (k, m) and G (6, k), got {J_h.shape}, {G.shape}'
            )
        self._J_h, self._G = J_h, G

    def add_tracker_sample(self, sample: TrackerSample) -> bool:
        """Correct the estimate with a tracker sample; False (ignored) if not newer.

        A sample captured at or before the newest one added is ignored.
        """
        t_c = sample.stamp_ns
        if self._sample_stamp_ns is not None and t_c <= self._sample_stamp_ns:
            return False
        if sample.twist_object is not None:
            self._sample_twist = np.array(sample.twist_object)
        if self._stamp_ns is None:
            self._stamp_ns = t_c
            self._p = np.array(sample.p_object_in_palm)
            self._R = np.array(sample.R_object_to_palm)
            self._twist = self._sample_twist.copy()
            self._remember()
        else:
            tau = self.config.correction_time
            dt_c = (t_c - self._sample_stamp_ns) * _NS
            gain = 1.0 if tau == 0.0 else -math.expm1(-dt_c / tau)
            gain = max(1.0 / (self._samples + 1), gain)
            p_hat, R_hat = self._pose_at(t_c)
            dp = gain * (sample.p_object_in_palm - p_hat)
            E = pin.exp3(gain * pin.log3(sample.R_object_to_palm @ R_hat.T))
            self._p = self._p + dp
            self._R = E @ self._R
            self._C = self._C + dp
            self._E = E @ self._E
        self._samples += 1
        self._sample_stamp_ns = t_c
        return True

    def estimate(self, stamp_ns: int, dq: np.ndarray) -> ObjectEstimate | None:
        """Return the object's state at the joint-state tick ``stamp_ns``; None without a pose.

        ``dq``: joint velocities at the tick, (m,), rad/s, in the model's joint order. A tick
        older than the newest estimate is answered from the history without moving the
        estimate back.
        """
        stamp_ns = _stamp('stamp_ns', stamp_ns)
        if self._stamp_ns is None:
            return None
        twist, source = self._twist_from(np.asarray(dq, dtype=float))
        if stamp_ns < self._stamp_ns:
            p, R = self._pose_at(stamp_ns)
        else:
            dt = (stamp_ns - self._stamp_ns) * _NS
            self._p, R = _moved(self._p, self._R, 0.5 * (self._twist + twist), dt)
            # One Newton step towards the nearest rotation: keeps R orthonormal to rounding
            # over any number of ticks (products of exp3 drift by ~1e-16 per tick).
            self._R = R @ (1.5 * np.eye(3) - 0.5 * R.T @ R)
            self._twist, self._stamp_ns = twist, stamp_ns
            self._remember()
            p, R = self._p, self._R
        age_ns = stamp_ns - self._sample_stamp_ns
        return ObjectEstimate(
            stamp_ns,
            _readonly(p),
            _readonly(R),
            _readonly(twist),
            age_ns * _NS,
            source,
            age_ns > self._max_age_ns,
        )

    # ------------------------------------------------------------------------------ private
    def _twist_from(self, dq: np.ndarray) -> tuple[np.ndarray, str]:
        """Return the kinematic twist ``lstsq(G^T, J_h dq)``, or the tracker's, and its source."""
        if self._G is None:
            return self._sample_twist.copy(), TRACKER
        if dq.shape != (self._J_h.shape[1],):
            raise ValueError(f'dq: expected shape ({self._J_h.shape[1]},), got {dq.shape}')
        with np.errstate(all='ignore'):
            rhs = self._J_h @ dq
        # The SVD needs finite input; it gives the rank and the condition number too.
        if np.isfinite(rhs).all() and np.isfinite(self._G).all():
            try:
                twist, _, rank, singular = np.linalg.lstsq(self._G.T, rhs, rcond=None)
            except np.linalg.LinAlgError:  # the SVD did not converge
                return self._sample_twist.copy(), TRACKER
            well_conditioned = rank == 6 and singular[-1] * MAX_GRASP_MAP_CONDITION >= singular[0]
            if well_conditioned and np.isfinite(twist).all():
                return twist, KINEMATICS
        return self._sample_twist.copy(), TRACKER

    def _remember(self) -> None:
        """Append the current estimate to the history and drop what is older than it keeps."""
        entry = (self._p - self._C, self._E.T @ self._R, self._twist)
        if self._stamps and self._stamps[-1] == self._stamp_ns:
            self._entries[-1] = entry
        else:
            self._stamps.append(self._stamp_ns)
            self._entries.append(entry)
        # Keep one entry at or before the window's start, so that it is covered.
        start = bisect_right(self._stamps, self._stamp_ns - self._history_ns) - 1
        if start > 0:
            del self._stamps[:start]
            del self._entries[:start]

    def _entry(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return history entry ``index`` as ``(p, R, twist)`` with the corrections applied."""
        p, R, twist = self._entries[index]
        return p + self._C, self._E @ R, twist

    def _pose_at(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the estimated pose at ``stamp_ns``: the history interpolated or extrapolated."""
        index = bisect_right(self._stamps, stamp_ns)
        if index == 0 or index == len(self._stamps):
            end = 0 if index == 0 else -1
            p, R, twist = self._entry(end)
            return _moved(p, R, twist, (stamp_ns - self._stamps[end]) * _NS)
        t0, t1 = self._stamps[index - 1], self._stamps[index]
        p0, R0, _ = self._entry(index - 1)
        p1, R1, _ = self._entry(index)
        s = (stamp_ns - t0) / (t1 - t0)
        return p0 + s * (p1 - p0), pin.exp3(s * pin.log3(R1 @ R0.T)) @ R0
