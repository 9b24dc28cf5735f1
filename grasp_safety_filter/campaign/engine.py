"""Where a campaign's runs execute: Dask distributed, on this machine's cores or a cluster.

Dask distributed is the engine: it runs plain Python functions on a local cluster of
processes or on any cluster a scheduler serves (SSH, Kubernetes, and SLURM, PBS, SGE or LSF
through ``dask-jobqueue``), reschedules the runs of a worker that dies, and is a pure-Python
install. (Ray would do as well, but brings a 70 MB native runtime and its own object store,
which runs of a few kilobytes of input and output do not need.)

Every run is submitted at once; each finished run is kept on disk by the
:class:`~grasp_safety_filter.campaign.store.ResultStore` before the next is awaited, so a
stop loses none. A run whose worker died three times (``KilledWorker``) is recorded as
failed, like a run that raised.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import CancelledError
import contextlib
import logging
import os
import signal
from typing import Any

from grasp_safety_filter.campaign.run import execute_run, failed_outcome, identity
from grasp_safety_filter.campaign.spec import RunSpec
from grasp_safety_filter.campaign.store import ResultStore

#: Dask settings of the local cluster's workers. Dask's statistical profiler samples the
#: running thread every 10 ms and takes the GIL to do it: off, a run's CPU drops by about
#: a tenth (docs/campaigns.md). A cluster's workers: DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED.
LOCAL_WORKER_CONFIG = {
    'distributed.worker.profile.enabled': False,
    'distributed.admin.system-monitor.interval': '2s',
}


class SchedulerLostError(ConnectionError):
    """The scheduler went away with runs pending: they are not results, and run again later."""


Progress = Callable[[dict[str, Any]], None]
"""Called with each finished run's row."""


def default_workers() -> int:
    """One worker per core this process may use."""
    return (
        len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count() or 1
    )


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Any]:
    """Yield a Dask client: of the scheduler at ``scheduler``, or of a local cluster.

    The local cluster has ``workers`` single-threaded worker processes (default: one per
    core) and no dashboard; it is shut down on exit. Call from the main thread.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as client:
            yield client
        return
    # The workers start with SIGINT ignored (inherited): a Ctrl-C at the terminal reaches the
    # whole process group, and it is this process's to stop the campaign and the cluster.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with dask.config.set(LOCAL_WORKER_CONFIG):  # handed to the worker processes
            cluster = LocalCluster(
                n_workers=workers or default_workers(),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
    finally:
        signal.signal(signal.SIGINT, previous)
    with cluster, Client(cluster) as client:
        yield client


def execute(
    runs: Sequence[RunSpec],
    store: ResultStore,
    client: Any,
    progress: Progress | None = None,
) -> int:
    """Run every run of ``runs`` not yet in ``store``; return how many were run.

    Each row is appended to ``store`` as its run finishes. An interrupt (Ctrl-C) or a lost
    scheduler propagates; the runs that finished before it are kept.
    """
    from distributed import as_completed

    pending = [run for run in runs if run.key not in store.finished]
    if not pending:
        return 0
    futures = {
        client.submit(execute_run, run, key=f'grasp-run-{run.key}', pure=False): run
        for run in pending
    }
    done = 0
    try:
        for future in as_completed(futures):
            run = futures[future]
            try:
                row = future.result()
            except CancelledError:
                # The client cancels every future when it loses the scheduler: not a result.
                raise SchedulerLostError('runs cancelled: the scheduler was lost') from None
            except Exception as error:  # the worker died (KilledWorker) or could not load it
                row = {**identity(run), **failed_outcome(f'{type(error).__name__}: {error}')}
            store.append(row)
            done += 1
            if progress is not None:
                progress(row)
    finally:
        with contextlib.suppress(Exception):  # a lost scheduler cannot be told
            client.cancel(list(futures))
    return done
