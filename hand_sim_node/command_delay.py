"""The simulator's command delay: a delay line of whole integration steps.

With ``command_delay`` = k ``time_step`` (parameter of ``hand_sim_node``, lockstep mode) the
plant applies the command of tick t_n over the step from t_(n+k): an actuator or
communication delay between the controller and the hand. Until the first delayed command is
due (the first k steps) the plant applies the first command it received. k = 0: each
command at its own tick.
"""

from __future__ import annotations

from collections import deque

import numpy as np


class CommandDelay:
    """Delay each step's command by ``steps`` steps (module docstring).

    Args:
        steps: The delay in integration steps, ``>= 0``.

    """

    def __init__(self, steps: int) -> None:
        if steps < 0:
            raise ValueError(f'command delay: expected >= 0 steps, got {steps}')
        self.steps = int(steps)
        self._line: deque[np.ndarray] = deque()

    def reset(self) -> None:
        """Forget the commands held (a new run)."""
        self._line.clear()

    def __call__(self, command: np.ndarray) -> np.ndarray:
        """Take the command of this step; return the one the plant applies over it.

        That is the command taken ``steps`` calls ago, or the first one taken while fewer
        calls than that have been made.
        """
        if self.steps == 0:
            return command
        self._line.append(np.array(command, dtype=float))
        return self._line.popleft() if len(self._line) > self.steps else self._line[0]
