"""``grasp-bench-realtime``'s lean driver: a hand's driver and tracker, replaying a recording.

Run as a process (``python -m grasp_tools.bench.real_time_driver INPUT --out OUT``)
it stands in for a real hand's driver that is not Python: plain rclpy publishers, never
spun, and a loop that sleeps to its next event on ``time.monotonic``. Everything it
publishes is computed beforehand (:func:`driver_plan`, written by :func:`write_driver_input`)
from the paper's recorded filtered run (:mod:`.real_time_recording`: q, dq, object pose and
twist, u_nom and the applied u* every 1 ms step), so the loop does no arithmetic:

- every period k it publishes ``/hand/joint_states`` (q, dq, applied effort) of the
  recording at ``k * period``, stamped with ``time.time_ns()`` when it publishes, then
  ``/hand/effort_nominal`` (the recording's u_nom) stamped exactly as that state, as the
  package's nominal controller does;
- the tracker captures the object's pose every ``1 / tracker_rate`` (on the recording's
  1 ms grid), with Gaussian noise (position: ``noise`` m per axis; orientation:
  ``pinocchio.exp3`` of ``orientation_noise`` rad per axis), and publishes it ``latency``
  s later, stamped with its capture time (``/object/odom`` with the recorded twist, or
  ``/object/pose``).

It writes what it did to ``OUT`` (JSON): each state's stamp and how late it went out after
its due time, and the same of each tracker sample.
"""

from __future__ import annotations

import argparse
from array import array
from dataclasses import dataclass
import json
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

from grasp_tools.bench.real_time_recording import Recording

#: Event kinds of the driver's loop; at equal times a state goes out before a tracker sample.
STATE, TRACKER = 0, 1

#: Orientation noise of the tracker, rad per axis (a motion-capture system's, 0.3 degrees).
ORIENTATION_NOISE = 0.005

#: Subscriptions the driver waits for before it starts: per topic table name, how many.
SUBSCRIBERS = {'joint_states': 2, 'effort_nominal': 1, 'tracker': 1}


@dataclass(frozen=True, eq=False)
class DriverPlan:
    """What the driver publishes when, as offsets from its start, ns.

    Attributes:
        period_ns: The driver's period, ns.
        state_offsets: Due time of each state, ns.
        state_rows: The recording's row of each state.
        capture_offsets: Capture time of each tracker sample (its stamp), ns.
        capture_rows: The recording's row of each tracker sample.
        release_offsets: Due time of each tracker sample: capture + latency, ns.
        position: Each sample's noisy position, shape (c, 3), m.
        rotation: Each sample's noisy orientation, shape (c, 3, 3).
    """

    period_ns: int
    state_offsets: np.ndarray
    state_rows: np.ndarray
    capture_offsets: np.ndarray
    capture_rows: np.ndarray
    release_offsets: np.ndarray
    position: np.ndarray
    rotation: np.ndarray

    def events(self) -> list[tuple[int, int, int]]:
        """Return the driver's publications in order (:func:`publication_events`)."""
        return publication_events(self.state_offsets, self.release_offsets)


def publication_events(
    state_offsets: np.ndarray, release_offsets: np.ndarray
) -> list[tuple[int, int, int]]:
    """Return ``(due offset ns, STATE or TRACKER, index)`` of every publication, in order."""
    states = [(int(t), STATE, k) for k, t in enumerate(state_offsets)]
    samples = [(int(t), TRACKER, j) for j, t in enumerate(release_offsets)]
    return sorted(states + samples)


def driver_plan(
    recording: Recording,
    rate: float,
    duration: float,
    tracker_rate: float,
    latency: float,
    noise: float,
    orientation_noise: float = ORIENTATION_NOISE,
    seed: int = 0,
) -> DriverPlan:
    """Return the driver's schedule and the tracker's noisy samples (module docstring).

    Args:
        recording: The run to replay.
        rate: The driver's rate, Hz; its period is taken as a whole number of the
            recording's steps (333 Hz: 3 ms).
        duration: How long the driver publishes, s.
        tracker_rate: The tracker's rate, Hz (its captures on the recording's steps).
        latency: Capture to publication, s.
        noise: Position noise, standard deviation per axis, m.
        orientation_noise: Orientation noise, standard deviation per axis, rad.
        seed: Of the noise.

    Raises:
        ValueError: A rate that is not a whole number of steps to within 1 %, or a
            recording shorter than ``duration``.
    """
    import pinocchio as pin

    step = recording.time_step_ns
    stride = max(1, round(1e9 / rate / step))
    if abs(stride * step * rate / 1e9 - 1.0) > 0.01:
        raise ValueError(f'rate {rate} Hz: the period must be a whole number of {step} ns steps')
    periods = round(duration * rate)
    state_rows = np.arange(periods) * stride
    if periods == 0 or state_rows[-1] >= recording.steps:
        raise ValueError(
            f'the recording holds {recording.steps * step / 1e9} s, the driver needs {duration} s'
        )
    end = int(state_rows[-1]) * step
    latency_ns = round(latency * 1e9)
    captures = np.arange(max(0, int(np.floor(tracker_rate * end / 1e9)) + 1))
    capture_rows = np.round(captures * 1e9 / tracker_rate / step).astype(np.int64)
    capture_rows = capture_rows[capture_rows * step + latency_ns <= end]  # out while it runs
    capture_offsets = capture_rows * step
    rng = np.random.default_rng(seed)
    position = recording.position[capture_rows] + rng.normal(0.0, noise, (len(capture_rows), 3))
    tilts = rng.normal(0.0, orientation_noise, (len(capture_rows), 3))
    rotation = np.array(
        [pin.exp3(w) @ R for w, R in zip(tilts, recording.rotation[capture_rows], strict=True)]
    ).reshape(-1, 3, 3)
    return DriverPlan(
        period_ns=stride * step,
        state_offsets=state_rows * step,
        state_rows=state_rows,
        capture_offsets=capture_offsets,
        capture_rows=capture_rows,
        release_offsets=capture_offsets + latency_ns,
        position=position,
        rotation=rotation,
    )


def write_driver_input(
    path: Path, recording: Recording, plan: DriverPlan, object_message: str = 'odometry'
) -> Path:
    """Write what the driver process publishes (its ``INPUT``) as an ``.npz`` file."""
    rows = plan.state_rows
    np.savez(
        path,
        period_ns=plan.period_ns,
        joint_names=np.array(recording.joint_names),
        frames=np.array([recording.palm_frame, recording.object_frame]),
        object_message=np.array(object_message),
        state_offsets=plan.state_offsets,
        q=recording.q[rows],
        dq=recording.dq[rows],
        u=recording.u[rows],
        u_nom=recording.u_nom[rows],
        capture_offsets=plan.capture_offsets,
        release_offsets=plan.release_offsets,
        position=plan.position,
        rotation=plan.rotation,
        twist=recording.twist[plan.capture_rows],
    )
    return path


# ------------------------------------------------------------------------------ the process
def _tracker_messages(msgs: Any, data: Any, pose: bool) -> list[Any]:
    """Build every tracker message beforehand (stamped at publication)."""
    from grasp_safety_filter.io import messages as m

    palm, obj = (str(s) for s in data['frames'])
    built = []
    for p, R, twist in zip(data['position'], data['rotation'], data['twist'], strict=True):
        if pose:
            built.append(m.pose_stamped_to_msg(msgs, 0, p, R, frame_id=palm))
        else:
            built.append(m.odometry_to_msg(msgs, 0, p, R, twist, palm, obj))
    return built


def _set_stamp(msg: Any, stamp: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)


def _wait_for_subscribers(publishers: dict[str, Any], timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while any(p.get_subscription_count() < SUBSCRIBERS[k] for k, p in publishers.items()):
        if time.monotonic() > deadline:
            counts = {k: p.get_subscription_count() for k, p in publishers.items()}
            raise RuntimeError(f'driver: subscribers {counts}, expected {SUBSCRIBERS}')
        time.sleep(0.05)


def run_driver(input_path: Path, out_path: Path, connect_timeout: float, settle: float) -> int:
    """Publish the plan of ``input_path`` (module docstring); write the records to ``out_path``."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from grasp_safety_filter.io import messages as m
    from grasp_safety_filter.io import topics
    from grasp_safety_filter.io.interrupts import record_termination_requests

    termination = record_termination_requests()
    data = dict(np.load(input_path))
    pose = str(data['object_message']) == 'pose'
    names = [str(s) for s in data['joint_names']]
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('bench_driver')
    msgs = m.MessageNamespace.from_rclpy()
    tracker_topic = topics.OBJECT_POSE if pose else topics.OBJECT_ODOM
    publishers = {
        key: node.create_publisher(
            m.rclpy_message_class(topics.topic_spec(topic).msgtype),
            topic,
            topics.topic_spec(topic).qos.to_rclpy(),
        )
        for key, topic in (
            ('joint_states', topics.JOINT_STATES),
            ('effort_nominal', topics.EFFORT_NOMINAL),
            ('tracker', tracker_topic),
        )
    }
    state_msg = m.joint_state_to_msg(msgs, 0, names, data['q'][0], data['dq'][0], data['u'][0])
    nominal_msg = m.effort_to_msg(msgs, 0, names, data['u_nom'][0])
    # Each period's fields as rclpy takes them without a conversion: array('d').
    rows = [
        tuple(array('d', values) for values in period)
        for period in zip(data['q'], data['dq'], data['u'], data['u_nom'], strict=True)
    ]
    samples = _tracker_messages(msgs, data, pose)
    state_offsets = data['state_offsets'].tolist()
    events = publication_events(data['state_offsets'], data['release_offsets'])
    captures = data['capture_offsets'].tolist()
    stamps: list[int] = []
    lateness: list[int] = []
    tracker: list[tuple[int, int]] = []
    publish_state = publishers['joint_states'].publish
    publish_nominal = publishers['effort_nominal'].publish
    publish_tracker = publishers['tracker'].publish
    try:
        _wait_for_subscribers(publishers, connect_timeout)
        time.sleep(settle)  # discovery completes in both directions
        start = time.monotonic_ns()
        origin = time.time_ns()
        for offset, kind, index in events:
            if termination.requested:
                break
            due = start + offset
            wait = due - time.monotonic_ns()
            if wait > 0:
                time.sleep(wait / 1e9)
            if kind == STATE:
                stamp, late = time.time_ns(), time.monotonic_ns() - due
                q, dq, u, u_nom = rows[index]
                _set_stamp(state_msg, stamp)
                state_msg.position, state_msg.velocity, state_msg.effort = q, dq, u
                publish_state(state_msg)
                _set_stamp(nominal_msg, stamp)
                nominal_msg.effort = u_nom
                publish_nominal(nominal_msg)
                stamps.append(stamp)
                lateness.append(late)
            else:
                sample = samples[index]
                _set_stamp(sample, origin + captures[index])
                late = time.monotonic_ns() - due
                publish_tracker(sample)
                tracker.append((origin + captures[index], late))
    finally:
        out_path.write_text(
            json.dumps(
                {
                    'period_ns': int(data['period_ns']),
                    'planned_states': len(state_offsets),
                    'stamps': stamps,
                    'lateness_ns': lateness,
                    'tracker': tracker,
                }
            ),
            encoding='utf-8',
        )
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the driver process (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('input', type=Path, help='the plan (write_driver_input)')
    parser.add_argument('--out', type=Path, required=True, help='records (JSON)')
    parser.add_argument('--connect-timeout', type=float, default=60.0, help='s (60)')
    parser.add_argument('--settle', type=float, default=0.5, help='s after connecting (0.5)')
    args = parser.parse_args(argv)
    return run_driver(args.input, args.out, args.connect_timeout, args.settle)


if __name__ == '__main__':
    sys.exit(main())
