"""One piece of work done beside the caller, in a forked process: the analysis on 2 cores.

Reading a bag and drawing its figures are pure Python loops, one core each; split in two
independent halves (topics, figures), one half runs in a child process while the caller
does the other. :class:`ForkedCall` is that child: forked (the caller's modules and data
come along, nothing is imported again), its result sent back pickled.

It is an optimisation only, never a second way to fail: the caller asks
:meth:`ForkedCall.result` and, on :class:`ForkedCallError` (no fork on this platform, the
child raised, died or was killed), does the child's half itself, so that what it returns
or raises is what the one-process analysis returns or raises.

The child ignores SIGINT (a Ctrl-C reaches the whole process group: the caller decides
what an interrupt does) and is killed by :meth:`ForkedCall.close` if still running. Both
signals are blocked across the fork, so that none reaches the child before it has set its
own handling. A child that the caller stops itself, through a channel of their own,
ignores SIGTERM too (``leave_signals_to_parent``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import multiprocessing
from multiprocessing.connection import Connection
import signal
import time
from typing import Any, Generic, TypeVar

from grasp_safety_filter.io.interrupts import leave_signals_to_parent, TERMINATION_SIGNALS

Result = TypeVar('Result')


class ForkedCallError(RuntimeError):
    """The forked call gave no result (it raised, died, or could not start)."""


def _mask(how: int, signals: Iterable[int]) -> set[int]:
    """``signal.pthread_sigmask`` where the platform has it (it has fork then, too)."""
    if hasattr(signal, 'pthread_sigmask'):
        return set(signal.pthread_sigmask(how, signals))
    return set()


def _child(work: Callable[[], Any], sender: Connection, leave_signals: bool) -> None:
    """Run ``work`` in the child; send ``(True, result)`` or ``(False, error text)``."""
    if leave_signals:
        leave_signals_to_parent()
    else:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _mask(signal.SIG_UNBLOCK, TERMINATION_SIGNALS)
    try:
        outcome: tuple[bool, Any] = (True, work())
    except BaseException as error:  # reported to the caller, who redoes the work
        outcome = (False, f'{type(error).__name__}: {error}')
    try:
        sender.send(outcome)
    except Exception as error:  # e.g. a result that does not pickle
        sender.send((False, f'{type(error).__name__}: {error}'))
    finally:
        sender.close()


def _exit_text(exit_code: int | None) -> str:
    """Say how a child ended, from its exit status (negative: killed by that signal)."""
    if exit_code is None:
        return 'not reaped'
    if exit_code < 0:
        try:
            return f'killed by {signal.Signals(-exit_code).name}'
        except ValueError:
            return f'killed by signal {-exit_code}'
    return f'exit status {exit_code}'


class ForkedCall(Generic[Result]):
    """``work()`` running in a forked child from construction on (module docstring).

    Use as a context manager (or call :meth:`close`): the child is reaped, or killed if the
    caller leaves before taking its result.
    """

    #: Least time the caller waits for the child's result, s (see :meth:`result`).
    least_wait = 30.0

    def __init__(
        self, work: Callable[[], Result], daemon: bool = True, leave_signals: bool = False
    ) -> None:
        """Fork a child that runs ``work`` (nothing starts where fork is unavailable).

        Args:
            work: What the child does; its result must pickle.
            daemon: Whether the child is a daemon process, which may not fork children of
                its own (an analysis's child); False for a child that runs an analysis.
            leave_signals: The child ignores SIGTERM too; the caller stops it its own way.

        """
        self._started = time.monotonic()
        self._process: Any = None
        self._receiver: Connection | None = None
        self._start_error: str | None = None
        #: The child's exit status once reaped (negative: the signal that ended it).
        self.exit_code: int | None = None
        blocked = _mask(signal.SIG_BLOCK, TERMINATION_SIGNALS)
        try:
            context = multiprocessing.get_context('fork')
            receiver, sender = context.Pipe(duplex=False)
            process = context.Process(
                target=_child, args=(work, sender, leave_signals), daemon=daemon
            )
            process.start()
        except (ValueError, OSError) as error:
            self._start_error = f'{type(error).__name__}: {error}'
            return
        finally:
            _mask(signal.SIG_SETMASK, blocked)
        sender.close()
        self._process, self._receiver = process, receiver

    @property
    def started(self) -> bool:
        """Whether a child was forked (False where fork is unavailable or failed)."""
        return self._start_error is None

    @property
    def start_error(self) -> str | None:
        """Why no child was forked, or None."""
        return self._start_error

    def ready(self, timeout: float = 0.0) -> bool:
        """Whether the child's result, or its end, can be taken without waiting.

        Args:
            timeout: Wait up to this long for it, s.

        """
        if self._receiver is None:
            return True
        try:
            return self._receiver.poll(timeout)
        except (EOFError, OSError):
            return True

    def result(self, wait: float | None = None) -> Result:
        """Wait for the child's result.

        The caller asks once its own half is done, which took about as long as the child's:
        by default it waits twice that since the fork, and at least :attr:`least_wait`, for
        a child that may have hung (a lock another thread held at the fork), then does the
        work itself.

        Args:
            wait: Wait this long instead, s.

        Raises:
            ForkedCallError: The child could not start, raised, died without a result, or
                gave none in time (it is then killed).

        """
        if self._receiver is None:
            raise ForkedCallError(self._start_error or 'no child process')
        if wait is None:
            wait = max(self.least_wait, 2.0 * (time.monotonic() - self._started))
        try:
            if not self._receiver.poll(wait):
                raise ForkedCallError(f'child gave no result in {wait:.0f} s')
            ok, value = self._receiver.recv()
        except (EOFError, OSError) as error:
            self.close(wait=True)
            raise ForkedCallError(
                f'child ended without a result ({error!r}, {_exit_text(self.exit_code)})'
            ) from None
        finally:
            self.close(wait=True)
        if not ok:
            raise ForkedCallError(value)
        return value

    def close(self, wait: bool = False) -> None:
        """Reap the child; kill it first if it is still running.

        Args:
            wait: Give a child that sent its result a second to exit before killing it.

        """
        process, receiver = self._process, self._receiver
        self._process = self._receiver = None
        if receiver is not None:
            receiver.close()
        if process is not None:
            if wait:
                process.join(timeout=1.0)
            if process.is_alive():
                process.kill()
            process.join()
            self.exit_code = process.exitcode
            process.close()

    def __enter__(self) -> ForkedCall[Result]:
        """Return this call."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Reap or kill the child (:meth:`close`)."""
        self.close()
