"""What a lockstep run is asked to do and what it returns: its options and results."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import node_overrides, override_errors
from hand_sim_node.event_log import EventLog

#: The filter off (``u* = u_nom``) or on; also the subdirectories of a ``--mode both`` output.
MODES = ('nominal', 'filtered')

__all__ = ['MODES', 'Recording', 'RunOptions', 'RunResult', 'node_overrides']


@dataclass(frozen=True)
class RunOptions:
    """What to run.

    Attributes:
        config: Scenario parameter file (ROS 2 format).
        mode: ``"nominal"`` (filter off: u* = u_nom) or ``"filtered"``.
        duration: Overrides the scenario's ``duration`` (s), if given.
        time_step: Overrides ``time_step`` (s), if given.
        integrator: Overrides ``integrator`` (``"ode3"`` or ``"rk4"``), if given.
        storage: Bag storage, ``"mcap"`` (default, as ``ros2 bag record``) or ``"sqlite3"``.
        overrides: ``{key: value}`` replacing the scenario file's parameters. A key is a
            dotted name, for every node that declares it (e.g.
            ``{"barrier.alpha1.gain": 10.0}``), or ``NODE/NAME``, for that node only (e.g.
            ``{"hand_sim_node/model.friction_coefficient": 0.6}``: a plant whose μ is not
            the controllers' model's); for its node ``NODE/NAME`` beats ``NAME``. What
            applies to one node: :func:`node_overrides`.
        animate: Also draw the run's ``animation.gif``.
    """

    config: Path
    mode: str = 'filtered'
    duration: float | None = None
    time_step: float | None = None
    integrator: str | None = None
    storage: str = 'mcap'
    overrides: Mapping[str, Any] = field(default_factory=dict)
    animate: bool = False

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f'mode: expected one of {list(MODES)}, got {self.mode!r}')
        errors = override_errors(self.overrides)
        if errors:
            raise ParameterError('; '.join(errors))


@dataclass(frozen=True)
class Recording:
    """What the live run itself observed, to compare with what its bag says.

    Attributes:
        interrupted: None when the simulator finished (ran to its duration or stopped on a
            violation), else the signal that interrupted it (``"SIGINT"`` or ``"SIGTERM"``;
            a run ended by another exception raises it instead).
        live_log: The plant's own constraint record of the run.
        stop_reason: The plant's stop reason (``"duration"`` when it ran to the end).
        t_end: Simulated time reached, s.
    """

    interrupted: str | None
    live_log: EventLog
    stop_reason: str | None
    t_end: float


@dataclass(frozen=True)
class RunResult:
    """Where a run's results are and what they say."""

    out_dir: Path
    bag: Path
    summary: dict[str, Any]
    figures: list[Path]
    wall_time: float
    recording: Recording
