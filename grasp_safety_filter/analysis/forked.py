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
what an interrupt does) and is killed by :meth:`ForkedCall.close` if still running.
"""

from __future__ import annotations

from collections.abc import Callable
import multiprocessing
from multiprocessing.connection import Connection
import signal
import time
from typing import Any, Generic, TypeVar

Result = TypeVar('Result')


class ForkedCallError(RuntimeError):
    """The forked call gave no result (it raised, died, or could not start)."""


def _child(work: Callable[[], Any], sender: Connection) -> None:
    """Run ``work`` in the child; send ``(True, result)`` or ``(False, error text)``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
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


class ForkedCall(Generic[Result]):
    """``work()`` running in a forked child from construction on (module docstring).

    Use as a context manager (or call :meth:`close`): the child is reaped, or killed if the
    caller leaves before taking its result.
    """

    #: Least time the caller waits for the child's result, s (see :meth:`result`).
    least_wait = 30.0

    def __init__(self, work: Callable[[], Result]) -> None:
        """Fork a child that runs ``work`` (nothing starts where fork is unavailable)."""
        self._started = time.monotonic()
        self._process: Any = None
        self._receiver: Connection | None = None
        self._start_error: str | None = None
        try:
            context = multiprocessing.get_context('fork')
            receiver, sender = context.Pipe(duplex=False)
            process = context.Process(target=_child, args=(work, sender), daemon=True)
            process.start()
        except (ValueError, OSError) as error:
            self._start_error = f'{type(error).__name__}: {error}'
            return
        sender.close()
        self._process, self._receiver = process, receiver

    def result(self) -> Result:
        """Wait for the child's result.

        The caller asks once its own half is done, which took about as long as the child's:
        it waits twice that since the fork, and at least :attr:`least_wait`, for a child
        that may have hung (a lock another thread held at the fork), then does the work
        itself.

        Raises:
            ForkedCallError: The child could not start, raised, died without a result, or
                gave none in time (it is then killed).

        """
        if self._receiver is None:
            raise ForkedCallError(self._start_error or 'no child process')
        wait = max(self.least_wait, 2.0 * (time.monotonic() - self._started))
        try:
            if not self._receiver.poll(wait):
                raise ForkedCallError(f'child gave no result in {wait:.0f} s')
            ok, value = self._receiver.recv()
        except (EOFError, OSError) as error:
            raise ForkedCallError(f'child ended without a result ({error!r})') from None
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
            process.close()

    def __enter__(self) -> ForkedCall[Result]:
        """Return this call."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Reap or kill the child (:meth:`close`)."""
        self.close()
