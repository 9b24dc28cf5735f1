"""The paper's recorded filtered run, as ``grasp-bench-realtime``'s driver replays it.

:func:`record` runs the paper's scenario closed loop (simulator, nominal controller, safety
filter; :func:`~grasp_tools.bench.recorded_run.record_filtered_run`) and keeps every
1 ms step: q, dq, object pose and twist, u_nom and the applied u*. It takes about as long
as the run it records, so :func:`load_or_record` keeps it in an ``.npz`` file for later runs.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
from pathlib import Path

import numpy as np


@dataclass(frozen=True, eq=False)
class Recording:
    """The paper's filtered run, one row per simulator step.

    Attributes:
        time_step_ns: Step of the rows, ns.
        joint_names: The hand's joints, in the rows' order.
        palm_frame: Frame of the object's pose.
        object_frame: The object's frame (the odometry's child frame).
        q: Joint angles, shape (n, m), rad.
        dq: Joint velocities, shape (n, m), rad/s.
        u: The applied (filtered) torques, shape (n, m), N·m.
        u_nom: The nominal controller's torques, shape (n, m), N·m.
        position: Object position in the palm frame, shape (n, 3), m.
        rotation: Object orientation (object to palm), shape (n, 3, 3).
        twist: Object twist (v, w) in the palm frame, shape (n, 6), m/s and rad/s.
        digest: Of the parameter file it was recorded from.
    """

    time_step_ns: int
    joint_names: tuple[str, ...]
    palm_frame: str
    object_frame: str
    q: np.ndarray
    dq: np.ndarray
    u: np.ndarray
    u_nom: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    twist: np.ndarray
    digest: str

    @property
    def steps(self) -> int:
        """Return the number of rows."""
        return len(self.q)

    def save(self, path: Path) -> None:
        """Write the recording as an ``.npz`` file."""
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        np.savez(
            path,
            time_step_ns=self.time_step_ns,
            joint_names=np.array(self.joint_names),
            frames=np.array([self.palm_frame, self.object_frame]),
            digest=np.array(self.digest),
            **arrays,
        )

    @classmethod
    def load(cls, path: Path) -> Recording:
        """Read a recording written by :meth:`save`."""
        with np.load(path) as data:
            palm, obj = (str(s) for s in data['frames'])
            return cls(
                int(data['time_step_ns']),
                tuple(str(s) for s in data['joint_names']),
                palm,
                obj,
                digest=str(data['digest']),
                **{name: data[name] for name in _ARRAYS},
            )


_ARRAYS = ('q', 'dq', 'u', 'u_nom', 'position', 'rotation', 'twist')


def config_digest(config: Path) -> str:
    """Return the SHA-256 of a parameter file's bytes (a recording's provenance)."""
    return hashlib.sha256(Path(config).read_bytes()).hexdigest()


def record(config: Path, duration: float) -> Recording:
    """Run the paper's filtered closed loop for ``duration`` s and keep every step.

    Raises:
        RuntimeError: The run stopped before ``duration`` (the scenario is not the paper's).
    """
    from grasp_tools.bench.recorded_run import record_filtered_run, Scenario

    scenario = Scenario.load(Path(config))
    ticks, rate, _, _ = record_filtered_run(scenario, duration)
    if rate.stop_reason != 'duration':
        raise RuntimeError(f'the recorded run stopped at {rate.simulated} s: {rate.stop_reason}')
    model = scenario.model

    def stack(name: str) -> np.ndarray:
        return np.array([getattr(tick, name) for tick in ticks], dtype=float)

    return Recording(
        round(scenario.sim_config.time_step * 1e9),
        tuple(model.joint_names),
        model.palm_frame,
        model.object_frame,
        stack('q'),
        stack('dq'),
        stack('u'),
        stack('u_nom'),
        stack('p_object_in_palm'),
        stack('R_object_to_palm'),
        stack('twist_object'),
        config_digest(config),
    )


def load_or_record(config: Path, duration: float, path: Path | None = None) -> Recording:
    """Return a recording of at least ``duration`` s: ``path``'s if it fits, else a new one.

    A new recording is written to ``path`` when one is given, for later runs.
    """
    if path is not None and path.exists():
        recording = Recording.load(path)
        long_enough = recording.steps * recording.time_step_ns >= duration * 1e9
        if recording.digest == config_digest(config) and long_enough:
            return recording
    recording = record(config, duration)
    if path is not None:
        recording.save(path)
    return recording
