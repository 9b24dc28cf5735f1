"""Where a simulated run stands: its start, steps, stop reason, state and constraint log.

Both plants keep their run this way: our rigid model's :class:`~hand_sim_node.simulator.
Simulator` and :class:`~hand_sim_node.mujoco_plant.MuJoCoPlant` derive from
:class:`RunRecord`. A state's time is counted from the run's start in whole steps
(``t_0 + k time_step``: no round-off accumulates over a long run).
"""

from __future__ import annotations

from typing import Any, TYPE_CHECKING

import numpy as np

from grasp_safety_filter.model.grasp_model import state_of
from grasp_safety_filter.model.grasp_state import GraspState
from hand_sim_node.event_log import EventLog

if TYPE_CHECKING:
    from hand_sim_node.simulator import SimState


class RunRecord:
    """A run of a plant since its last reset (module docstring).

    Attributes:
        model: The grasp model (set by the plant).
        log: The constraint margins and events of every step since the reset.
    """

    model: Any

    def _restart(self, state: SimState) -> None:
        """Start a new run at ``state``: no step taken, no stop, an empty log."""
        self._t0 = state.t
        self._step_index = 0
        self._state = state
        self._grasp_state: GraspState | None = None
        self._stop_reason: str | None = None
        self.log = EventLog()

    @property
    def step_index(self) -> int:
        """Number of steps taken since the last reset."""
        return self._step_index

    @property
    def stop_reason(self) -> str | None:
        """Why the run stopped, or None while it may go on."""
        return self._stop_reason

    def grasp_state(self) -> GraspState:
        """Our model's terms at the current state (computed once per state)."""
        if self._grasp_state is None:
            self._grasp_state = state_of(self.model, self._state)
        return self._grasp_state

    def _checked_effort(self, effort: np.ndarray) -> np.ndarray:
        """Return the joint torque ``effort`` (m,), N·m, of a step as floats.

        Raises:
            RuntimeError: The run has stopped (call ``reset``).
            ValueError: ``effort`` has the wrong shape or is not finite.
        """
        step = f'{type(self).__name__}.step'
        if self._stop_reason is not None:
            raise RuntimeError(f'{step}: the run stopped ({self._stop_reason}); reset()')
        u = np.array(effort, dtype=float)
        m = self.model.n_joints
        if u.shape != (m,) or not np.all(np.isfinite(u)):
            raise ValueError(f'{step}: expected {m} finite joint torques, got {u.tolist()}')
        return u
