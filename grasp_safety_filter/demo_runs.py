"""``grasp-demo``'s runs: one after the other, or the nominal run beside the filtered one.

With ``--mode both`` the two runs are independent (their own endpoints, bags and output
directories), so on two cores the nominal run, the short one (the paper's stops at about
1.2 s), runs in a forked child while the process runs the filtered one. Each run's
outcome is a :class:`RunOutcome`; they are reported in the order of the runs, once both
are done, so what a user reads, and every file, is what the runs one after the other give.

Signals: the child ignores SIGINT and SIGTERM (a Ctrl-C reaches the whole process group,
and a signal handler that raises inside code that cannot take an exception, such as
numba's loading of a cached kernel, would fail the run with ``SystemError``). The process
decides: once its own run has been interrupted, or a signal came while it waited for the
child, it asks the child to stop through a shared byte, which the child's run reads at
each simulated step and then stops as that signal would stop it (its bag closed, with
its summary when it recorded a step). A child past its recording completes its analysis;
one that gives no outcome within ``ForkedCall.least_wait`` of the request is killed.

A child that cannot be forked is no failure: the runs are done one after the other. A
child that raises or dies is a failed run (exit code 1), reported as such.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
import mmap
import multiprocessing
from pathlib import Path
import signal
import sys
import time
from typing import Any

from grasp_safety_filter.analysis.forked import ForkedCall, ForkedCallError
from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.files import OutputError
from grasp_safety_filter.io.interrupts import interrupt_on_signals, SignalInterrupt
from grasp_safety_filter.run_types import RunOptions
from grasp_safety_filter.runner import Progress, run, RunInterrupted

#: Exit status of a run that failed (its process raised or died).
EXIT_RUN_FAILED = 1
#: Exit status of an output directory that cannot be written.
EXIT_OUTPUT_ERROR = 2
#: How often the process looks for a signal while it waits for the child, s.
POLL_PERIOD = 0.2


def fork_available() -> bool:
    """Whether this platform can run a run in a forked child (``--jobs 2``)."""
    return 'fork' in multiprocessing.get_all_start_methods()


@dataclass(frozen=True)
class Interruption:
    """What an interrupted run left (as :class:`~grasp_safety_filter.runner.RunInterrupted`).

    Attributes:
        signal: ``"SIGINT"`` or ``"SIGTERM"``.
        bag: The run's closed, readable bag, or None (interrupted before recording).
        summary: The run's ``summary.json``, or None (not written).

    """

    signal: str
    bag: Path | None
    summary: Path | None


@dataclass(frozen=True)
class RunOutcome:
    """How one run of ``grasp-demo`` ended; exactly one of the last three is set.

    Attributes:
        mode: ``"nominal"`` or ``"filtered"``.
        out_dir: The run's output directory.
        summary: The completed run's ``summary.json`` contents.
        interruption: What an interrupted run left.
        error: The line that says why the run failed, and ``exit_code`` its status.
        exit_code: 0 unless ``error``.

    """

    mode: str
    out_dir: Path
    summary: dict[str, Any] | None = None
    interruption: Interruption | None = None
    error: str | None = None
    exit_code: int = 0

    @property
    def completed(self) -> bool:
        """Whether the run ran to its end: its summary and figures are written."""
        return self.summary is not None


def run_outcome(
    options: RunOptions, out_dir: Path, progress: Progress | None, force: bool
) -> RunOutcome:
    """Run one run (:func:`~grasp_safety_filter.runner.run`) and say how it ended.

    Raises:
        Exception: An error that is no user error (a bug): it propagates.

    """
    mode = options.mode
    try:
        result = run(options, out_dir, progress, force=force)
    except ConfigError as error:
        line = config_error_line('grasp-demo', error)
        return RunOutcome(mode, out_dir, error=line, exit_code=EXIT_CONFIG_ERROR)
    except OutputError as error:
        return RunOutcome(mode, out_dir, error=f'grasp-demo: {error}', exit_code=EXIT_OUTPUT_ERROR)
    except RunInterrupted as interrupt:
        left = Interruption(interrupt.signal, interrupt.bag, interrupt.summary)
        return RunOutcome(mode, out_dir, interruption=left)
    return RunOutcome(mode, out_dir, summary=result.summary)


ProgressFor = Callable[[str], Progress | None]
"""The progress display of a run, by mode (None: none)."""


def one_after_the_other(
    runs: Sequence[tuple[RunOptions, Path]], progress_for: ProgressFor, force: bool
) -> Iterator[RunOutcome]:
    """Run each run in this process, in order; stop after one that did not complete."""
    for options, out_dir in runs:
        outcome = run_outcome(options, out_dir, progress_for(options.mode), force)
        yield outcome
        if not outcome.completed:
            return


class _StopRequest:
    """A byte shared with the forked child: the signal it is asked to stop as (0: none)."""

    def __init__(self) -> None:
        self._byte = mmap.mmap(-1, 1)  # anonymous and shared: the child sees it after fork

    def ask(self, signum: int) -> None:
        """Ask the child to stop as ``signum`` would stop it (the first request stays)."""
        if not self._byte[0]:
            self._byte[0] = int(signum)

    @property
    def signum(self) -> int:
        """The signal the child is asked to stop as (0: it is not)."""
        return self._byte[0]

    @property
    def asked(self) -> bool:
        """Whether the child has been asked to stop."""
        return bool(self._byte[0])

    def progress(self, t: float, duration: float) -> None:
        """Raise the requested interrupt (the child's progress, called at each step)."""
        if self._byte[0]:
            raise SignalInterrupt(self._byte[0])


def side_by_side(
    runs: Sequence[tuple[RunOptions, Path]], progress_for: ProgressFor, force: bool
) -> Iterator[RunOutcome]:
    """Run the first run in a forked child while this process does the second (module doc).

    Yields both outcomes in the order of ``runs`` once both runs are done; or, where no
    child can be forked, what :func:`one_after_the_other` yields.

    Raises:
        SignalInterrupt: A signal came while this process waited for the child and
            interrupted neither run: both completed (raised after both outcomes).

    """
    (child_options, child_dir), (own_options, own_dir) = runs
    stop = _StopRequest()
    with interrupt_on_signals():  # a signal while waiting for the child, even outside a run
        child = ForkedCall(
            lambda: run_outcome(child_options, child_dir, stop.progress, force),
            daemon=False,  # its analysis forks a child of its own
            leave_signals=True,
        )
        if not child.started:
            print(
                f'grasp-demo: no second process ({child.start_error}): the runs run one '
                'after the other',
                file=sys.stderr,
            )
            yield from one_after_the_other(runs, progress_for, force)
            return
        with child:
            try:
                own = run_outcome(own_options, own_dir, progress_for(own_options.mode), force)
            except BaseException as error:  # a bug in this run, or a signal between runs
                stop.ask(error.signum if isinstance(error, SignalInterrupt) else signal.SIGTERM)
                _child_outcome(child, child_options.mode, child_dir, stop)
                raise
            if own.interruption is not None:
                stop.ask(signal.Signals[own.interruption.signal])
            first = _child_outcome(child, child_options.mode, child_dir, stop)
    yield first
    yield own
    if stop.asked and first.completed and own.completed:
        raise SignalInterrupt(stop.signum)


def _child_outcome(
    child: ForkedCall[RunOutcome], mode: str, out_dir: Path, stop: _StopRequest
) -> RunOutcome:
    """Wait for the child's outcome; forward a signal that comes meanwhile; reap it.

    The child runs as long as its run takes; once asked to stop, it has ``least_wait``
    to end (it stops at its next step, or completes its analysis), else it is killed.
    """
    deadline = time.monotonic() + child.least_wait if stop.asked else None
    ready = False
    while not ready and (deadline is None or time.monotonic() < deadline):
        try:
            ready = child.ready(POLL_PERIOD)
        except SignalInterrupt as interrupt:
            if deadline is None:
                deadline = time.monotonic() + child.least_wait
            stop.ask(interrupt.signum)
    if ready:
        try:
            return child.result(wait=0.0)
        except ForkedCallError as error:
            reason = str(error)
    else:
        child.close()
        reason = f'asked to stop, it gave no result in {child.least_wait:.0f} s: killed'
    return RunOutcome(
        mode,
        out_dir,
        error=f'grasp-demo: [{mode}] the run failed in its own process: {reason}',
        exit_code=EXIT_RUN_FAILED,
    )
