"""SIGINT and SIGTERM as one exception raised where the program can take it, or as a request.

Python raises SIGINT's ``KeyboardInterrupt`` wherever the program is, possibly halfway
through appending a record to a bag; SIGTERM ends the process without any clean-up. Inside
:func:`interrupt_on_signals`, both raise :class:`SignalInterrupt` (a ``KeyboardInterrupt``),
but not inside :class:`deferred_interrupts` blocks (a bag record being written, a bag being
closed): there the interrupt waits until the block is done.

An interrupt is also held off where it could not propagate or would do harm, and delivered
again (the same signal, raised anew from another thread) until it lands in the program's own
code: in a weak-reference callback or ``__del__`` (Python would print it as "Exception
ignored in ..." and lose it); during an import (an extension module that runs Python code
while it initialises, as numpy imports ``datetime``, turns it into an ``ImportError``); in
numba's own Python code (its compiled code turns it into ``SystemError``, and one raised
while numba loads a cached kernel can break its typing context for the rest of the process).
A kernel compiled for the first time can take seconds: the interrupt then comes when it is
done.

A long-running node takes no exception at all: :class:`TerminationRequests` records the
signal and its loop ends at the next turn. A forked child whose parent decides when it stops
calls :func:`leave_signals_to_parent`: it ignores SIGINT and SIGTERM from then on, also
inside :func:`interrupt_on_signals`. A child starts with none of its parent's bookkeeping (a
pending or held signal was the parent's; the re-delivering thread is not forked).

This module imports nothing heavy: a console script can install the handlers before it
imports numpy, Pinocchio or rosbags.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
import os
from queue import SimpleQueue
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any

REDELIVERY_DELAY = 1e-3
"""Delay before an interrupt that could not be raised is sent again, s."""

IMPORT_REDELIVERY_DELAY = 10e-3
"""Delay before an interrupt held off an import or numba's code is sent again, s."""

#: Code of Python's import system: a frame of these on the stack means an import is running.
_IMPORT_SYSTEM = ('<frozen importlib._bootstrap>', '<frozen importlib._bootstrap_external>')


class SignalInterrupt(KeyboardInterrupt):
    """SIGINT or SIGTERM received inside :func:`interrupt_on_signals`.

    Attributes:
        signum: The signal number.

    """

    def __init__(self, signum: int) -> None:
        super().__init__(f'interrupted by {signal.Signals(signum).name}')
        self.signum = signum


def signal_name(error: KeyboardInterrupt) -> str:
    """Return ``"SIGTERM"``/``"SIGINT"`` for a :class:`SignalInterrupt`, else ``"SIGINT"``.

    A plain ``KeyboardInterrupt`` comes from Python's default SIGINT handler.
    """
    if isinstance(error, SignalInterrupt):
        return signal.Signals(error.signum).name
    return 'SIGINT'


#: The signals this package takes over: how a user or a launcher stops a process
#: (``ros2 launch`` sends SIGINT, then SIGTERM).
TERMINATION_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _InterruptState:
    """Signal bookkeeping of the main thread (handlers run there).

    ``held`` is a signal being sent again, raised on leaving the outermost block if it has not
    been by then; ``pending`` one deferred by a :class:`deferred_interrupts` block;
    ``closing``: the outermost block is restoring the previous handlers (a signal is held),
    ordered against the re-sending thread by ``lock``; ``outer_hook``: the
    ``sys.unraisablehook`` that the outermost block replaced.
    """

    installed = 0
    left_to_parent = False
    critical_depth = 0
    pending: int | None = None
    held: int | None = None
    closing = False
    lock = threading.Lock()
    outer_hook: Any = sys.__unraisablehook__


def _in_main_thread() -> bool:
    return threading.get_ident() == threading.main_thread().ident


def _on_stack(frame: FrameType | None, files: tuple[str, ...]) -> bool:
    """Whether ``frame`` or one of its callers runs code of a file starting with ``files``."""
    while frame is not None:
        if frame.f_code.co_filename.startswith(files):
            return True
        frame = frame.f_back
    return False


def importing(frame: FrameType | None) -> bool:
    """Whether ``frame`` or one of its callers is Python's import system at work."""
    return _on_stack(frame, _IMPORT_SYSTEM)


def in_numba(frame: FrameType | None) -> bool:
    """Whether ``frame`` or one of its callers is numba's own Python code (module doc)."""
    numba_file = getattr(sys.modules.get('numba'), '__file__', None)
    return numba_file is not None and _on_stack(frame, (os.path.dirname(numba_file) + os.sep,))


def _handle_signal(signum: int, frame: FrameType | None) -> None:
    if _InterruptState.closing:
        _InterruptState.held = signum
        return
    if _InterruptState.critical_depth > 0:
        # Inside a write or close: interrupt once the block is done.
        _InterruptState.pending, _InterruptState.held = signum, None
        return
    if (importing(frame) or in_numba(frame)) and _Redelivery.queue is not None:
        _InterruptState.held = signum
        _Redelivery.queue.put((signum, IMPORT_REDELIVERY_DELAY))
        return
    _InterruptState.held = None
    raise SignalInterrupt(signum)


class TerminationRequests:
    """A signal handler that records SIGINT and SIGTERM instead of raising.

    Python's default SIGINT handler raises wherever the main thread is (inside
    ``destroy_node``, an extension module's initialisation); rclpy's own handlers shut the
    context down from another thread, under a callback that may still be taking a message.
    A recorded request is looked at where the program can stop.
    """

    def __init__(self) -> None:
        self.received: list[int] = []

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        """Record ``signum`` (the signal handler's signature)."""
        self.received.append(signum)

    @property
    def requested(self) -> bool:
        """Whether SIGINT or SIGTERM arrived."""
        return bool(self.received)


def record_termination_requests() -> TerminationRequests:
    """Record :data:`TERMINATION_SIGNALS` from now on; return the record.

    A record installed earlier (a console entry point's, from the process's first instant)
    is kept, with what it holds: a signal received before this call is not lost.
    """
    installed = signal.getsignal(signal.SIGINT)
    termination = (
        installed if isinstance(installed, TerminationRequests) else TerminationRequests()
    )
    for signum in TERMINATION_SIGNALS:
        signal.signal(signum, termination)
    return termination


def leave_signals_to_parent() -> None:
    """Ignore SIGINT and SIGTERM from now on (a forked child: its parent stops it)."""
    _InterruptState.left_to_parent = True
    for signum in TERMINATION_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)


class _Redelivery:
    """A daemon thread that sends the process a signal again, when asked to."""

    queue: SimpleQueue[tuple[int, float]] | None = None

    @classmethod
    def start(cls) -> None:
        if cls.queue is None:
            cls.queue = SimpleQueue()
            threading.Thread(target=cls._run, name='signal-redelivery', daemon=True).start()

    @classmethod
    def _run(cls) -> None:
        assert cls.queue is not None
        while True:
            signum, delay = cls.queue.get()
            time.sleep(delay)  # let the main thread leave the hook, or the import, first
            with _InterruptState.lock:
                # Never onto the handlers the block restores: its exit raises it instead.
                if _InterruptState.installed > 0 and not _InterruptState.closing:
                    signal.raise_signal(signum)


def _redeliver_swallowed(unraisable: Any) -> None:
    """``sys.unraisablehook``: an interrupt raised where it cannot propagate is sent again.

    From another thread: raised here, its handler would run inside this hook, where its
    exception cannot propagate either (one that still runs here is sent again the same way).
    Any other unraisable exception goes to the hook the outermost block replaced.
    """
    if not isinstance(unraisable.exc_value, SignalInterrupt) or _Redelivery.queue is None:
        _InterruptState.outer_hook(unraisable)
        return
    signum = unraisable.exc_value.signum
    while True:
        try:
            _InterruptState.held = signum
            _Redelivery.queue.put((signum, REDELIVERY_DELAY))
            return  # no call after the put: the handler cannot run between here and the caller
        except SignalInterrupt as again:
            signum = again.signum


@contextmanager
def interrupt_on_signals(
    signals: Sequence[signal.Signals] = TERMINATION_SIGNALS,
) -> Iterator[None]:
    """Turn ``signals`` into :class:`SignalInterrupt`, except inside deferred_interrupts.

    Installs the handlers (and the hook that re-delivers an interrupt Python could not
    raise) on entry and restores the previous ones on exit; a signal still being sent again
    then is raised as the block ends, not left to the restored handlers. Off the main
    thread (a run on a campaign's worker) it does nothing: Python delivers signals to the
    main thread only, and the thread's owner handles them.

    Raises:
        SignalInterrupt: On leaving the outermost block, for a signal held until then.

    """
    if not _in_main_thread():
        yield
        return
    if _InterruptState.left_to_parent:
        signals = [s for s in signals if s not in TERMINATION_SIGNALS]
    _Redelivery.start()
    previous = {s: signal.signal(s, _handle_signal) for s in signals}
    previous_hook = sys.unraisablehook
    _InterruptState.installed += 1
    outermost = _InterruptState.installed == 1
    if outermost:
        _InterruptState.outer_hook = previous_hook
    sys.unraisablehook = _redeliver_swallowed
    completed = False
    held = None
    try:
        yield
        completed = True
    finally:
        if outermost:
            with _InterruptState.lock:
                _InterruptState.closing = True
        try:
            sys.unraisablehook = previous_hook
            for s, handler in previous.items():
                signal.signal(s, handler)  # runs a signal already on its way: held
        finally:
            _InterruptState.installed -= 1
            if outermost:
                held, _InterruptState.held = _InterruptState.held, None
                _InterruptState.pending = None
                _InterruptState.closing = False
    if completed and held is not None:
        raise SignalInterrupt(held)


def _forget_parent_state() -> None:
    """Start a forked child with none of its parent's signal bookkeeping (module doc)."""
    _InterruptState.pending = _InterruptState.held = None
    _InterruptState.closing = False
    _InterruptState.lock = threading.Lock()  # another thread may have held it at the fork
    _Redelivery.queue = None  # its thread was not forked: start() starts one anew


if hasattr(os, 'register_at_fork'):
    os.register_at_fork(after_in_child=_forget_parent_state)


class deferred_interrupts(AbstractContextManager[None]):  # noqa: N801 (used as a function)
    """Hold :func:`interrupt_on_signals` interrupts off a block that must complete.

    A class rather than a generator: a bag enters one per message written, and a
    generator's context manager costs several times as much to enter and leave.

    Args:
        raise_pending: Raise a signal that arrived during the block after it (when it
            completed); else drop it (the caller is already stopping on an earlier one).

    """

    __slots__ = ('_counted', '_raise_pending')

    def __init__(self, raise_pending: bool = True) -> None:
        self._raise_pending = raise_pending
        self._counted = False

    def __enter__(self) -> None:
        if _in_main_thread():
            _InterruptState.critical_depth += 1
            self._counted = True

    def __exit__(self, exc_type: Any, exc_value: Any, traceback: Any) -> None:
        if not self._counted:
            return
        self._counted = False
        _InterruptState.critical_depth -= 1
        if exc_type is not None:
            return  # the block's own exception propagates; a deferred interrupt waits
        if _InterruptState.critical_depth == 0 and _InterruptState.pending is not None:
            signum, _InterruptState.pending = _InterruptState.pending, None
            if self._raise_pending:
                raise SignalInterrupt(signum)
