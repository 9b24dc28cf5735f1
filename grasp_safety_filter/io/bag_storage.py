"""rosbags' storage writers with a durability policy: what a SIGKILL or a power loss costs.

On its own, rosbags' mcap writer keeps its open chunk in memory until it exceeds 1 MiB
(about 0.13 s of a paper run) and never syncs its file; its sqlite3 writer commits once, at
close. A writer killed by SIGKILL, the OOM killer or a power loss would leave an mcap file
without its last chunk, or a sqlite3 file with no message at all (and no
``metadata.yaml`` either way).

:class:`DurableWriter` bounds the loss by the bag's own timestamps (simulated time for
``grasp-demo``, arrival time for ``grasp-record``): an mcap chunk, or a sqlite3
transaction, never spans :data:`FLUSH_PERIOD_NS` of stamps (nor grows past
:data:`FLUSH_BYTES`), and each is synced to disk when it ends (sqlite's default
``synchronous=FULL``). It also holds an exclusive ``flock`` on its storage file while open,
so that a recovery (:mod:`grasp_safety_filter.io.bag_recovery`) tells a bag whose writer
died from one still being written; the kernel drops the lock with the process.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
import fcntl
import os
from pathlib import Path
from typing import BinaryIO, ClassVar, Literal

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

FLUSH_PERIOD_NS = 50_000_000
"""Longest span of stamps in one mcap chunk or sqlite3 transaction [ns] (50 ticks at 1 kHz)."""

FLUSH_BYTES = 2**20
"""Largest chunk or transaction (rosbags' own mcap chunk size), for stamps that stall."""


class BagLockedError(RuntimeError):
    """Another process holds the bag's storage file open for writing."""


def storage_files(bag: Path) -> list[Path]:
    """Return the mcap and sqlite3 files in a bag directory."""
    return sorted(p for p in bag.iterdir() if p.suffix in ('.mcap', '.db3') and p.is_file())


def needs_recovery(path: Path | str) -> bool:
    """Whether ``path`` is a bag directory with a storage file and no ``metadata.yaml``."""
    path = Path(path)
    return path.is_dir() and not (path / 'metadata.yaml').exists() and bool(storage_files(path))


def sync_paths(*paths: Path) -> None:
    """``fsync`` files or directories (their data and their directory entries)."""
    for path in paths:
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _take_lock(path: Path) -> int:
    """Take an exclusive ``flock`` on a file; return its descriptor (closing it unlocks).

    Raises:
        BagLockedError: A live process holds it (a writer still recording).

    """
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise BagLockedError(f'{path} is still open for writing by another process') from None
    return fd


@contextmanager
def writer_lock(path: Path) -> Iterator[None]:
    """Hold a storage file's writer lock for a block (:func:`_take_lock`)."""
    fd = _take_lock(path)
    try:
        yield
    finally:
        os.close(fd)


class PacedMcapWriter(McapWriter):
    """rosbags' mcap storage, closing a chunk every ``flush_period_ns`` of stamps and syncing it.

    ``flush_period_ns`` None keeps rosbags' own policy (1 MiB chunks, no sync).
    """

    flush_period_ns: int | None = FLUSH_PERIOD_NS
    bio: BinaryIO

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        """Write a message, first closing the open chunk if it would span the period."""
        period = self.flush_period_ns
        if (
            period is not None
            and self.chunk.msgs
            and timestamp - self.chunk.message_start_time >= period
        ):
            self.close_chunk()
        super().write(connection, timestamp, data)  # closes a chunk past 1 MiB itself

    def close_chunk(self) -> None:
        """Close the open chunk and put it on disk (chunk and message indexes)."""
        super().close_chunk()
        if self.flush_period_ns is not None:
            self.bio.flush()
            os.fsync(self.bio.fileno())


class CommittingSqlite3Writer(Sqlite3Writer):
    """rosbags' sqlite3 storage, committing every ``flush_period_ns`` of stamps.

    The first commit, before the first message, makes the topics durable. ``flush_period_ns``
    None keeps rosbags' own policy (one transaction, committed at close).
    """

    flush_period_ns: int | None = FLUSH_PERIOD_NS

    def __init__(self, path: Path, compression: object) -> None:
        """Create the database (see ``Sqlite3Writer``)."""
        super().__init__(path, compression)  # type: ignore[arg-type]
        self._batch_start: int | None = None
        self._batch_bytes = 0

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        """Insert a message, first committing if the transaction would span the period."""
        period = self.flush_period_ns
        if period is not None and (
            self._batch_start is None
            or timestamp - self._batch_start >= period
            or self._batch_bytes >= FLUSH_BYTES
        ):
            self.conn.commit()
            self._batch_start, self._batch_bytes = timestamp, 0
        super().write(connection, timestamp, data)
        if self._batch_start is not None:
            self._batch_start = min(self._batch_start, timestamp)
            self._batch_bytes += len(data)


class DurableWriter(Writer):
    """rosbags' ``Writer`` with the storages above, its storage file locked while open.

    ``close`` also syncs the storage file, ``metadata.yaml`` and the bag directory, so a
    closed bag survives a power loss too.
    """

    STORAGE_PLUGINS: ClassVar[Mapping[StoragePlugin, type]] = {
        StoragePlugin.SQLITE3: CommittingSqlite3Writer,
        StoragePlugin.MCAP: PacedMcapWriter,
    }

    def __init__(
        self,
        path: Path | str,
        *,
        version: Literal[8, 9],
        storage_plugin: StoragePlugin,
        flush_period_ns: int | None = FLUSH_PERIOD_NS,
    ) -> None:
        """Prepare the bag (see ``Writer``); ``flush_period_ns`` None: rosbags' own policy."""
        super().__init__(path, version=version, storage_plugin=storage_plugin)
        if flush_period_ns is not None and flush_period_ns <= 0:
            raise ValueError(f'flush_period_ns: expected > 0 or None, got {flush_period_ns}')
        self.flush_period_ns = flush_period_ns
        self._lock: int | None = None
        self._storage_path: Path | None = None

    def open(self) -> None:
        """Create the bag and its storage file, and lock the file."""
        super().open()
        storage = self.storage
        assert isinstance(storage, (PacedMcapWriter, CommittingSqlite3Writer))
        storage.flush_period_ns = self.flush_period_ns
        self._storage_path = storage.path
        self._lock = _take_lock(storage.path)

    def close(self) -> None:
        """Close the storage, write ``metadata.yaml``, sync both, release the lock."""
        try:
            super().close()
            if self.flush_period_ns is not None and self._storage_path is not None:
                sync_paths(self._storage_path, self.metapath, self.path)
        finally:
            self._unlock()

    def abort(self) -> None:
        """Close without index and metadata (see ``Writer``), release the lock."""
        try:
            super().abort()
        finally:
            self._unlock()

    def _unlock(self) -> None:
        lock, self._lock = self._lock, None
        if lock is not None:
            os.close(lock)
