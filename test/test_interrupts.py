"""Interrupts that Python cannot raise where they arrive are delivered again, not lost."""

from __future__ import annotations

import signal
import time

import pytest

from grasp_safety_filter.io.interrupts import interrupt_on_signals, SignalInterrupt


class _SignalsWhenCollected:
    """An object whose finaliser receives a signal (as a weakref callback or GC may)."""

    def __init__(self, signum: signal.Signals) -> None:
        self.signum = signum

    def __del__(self) -> None:
        signal.raise_signal(self.signum)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_raised_inside_a_finaliser_reaches_the_program(signum, capsys):
    with interrupt_on_signals():
        with pytest.raises(SignalInterrupt) as interrupt:
            _SignalsWhenCollected(signum)  # collected at once: the handler runs in __del__
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.001)
    assert interrupt.value.signum == signum
    assert 'Exception ignored' not in capsys.readouterr().err
