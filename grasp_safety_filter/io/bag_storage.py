"""rosbags' storage writers with a durability policy: what a SIGKILL or a power loss costs.

On its own, rosbags' mcap writer keeps its open chunk in memory until it exceeds 1 MiB
(about 0.13 s of a paper run) and writes through a buffered file that is never synced; its
sqlite3 writer commits once, when the bag is closed. A writer killed by SIGKILL, the OOM
killer or a power loss therefore leaves an mcap file without its last chunk (and without
summary and ``metadata.yaml``), or a sqlite3 file with no message at all.

:class:`DurableWriter` is rosbags' ``Writer`` with two storage subclasses that bound the
loss by the bags' own timestamps (simulated time for ``grasp-demo``, arrival time for
``grasp-record``): an mcap chunk, or a sqlite3 transaction, never spans
:data:`FLUSH_PERIOD_NS` of stamps or more (nor grows past :data:`FLUSH_BYTES`); each
closed chunk is flushed and synced to disk, and each sqlite3 commit is synced by sqlite
(its default ``synchronous=FULL`` with a rollback journal). What a kill loses is the open
chunk or transaction: less than :data:`FLUSH_PERIOD_NS` of stamps before the message being
written. The writer also holds an exclusive ``flock`` on its storage file while open, so
that a recovery (:mod:`grasp_safety_filter.io.bag_recovery`) can tell a bag whose writer
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


def sync_paths(*paths: Path) -> None:
    """``fsync`` files or directories (their data and their directory entries)."""
    for path in paths:
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextmanager
def writer_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on a storage file (released when the process dies).

    Raises:
        BagLockedError: A live process holds it (a writer still recording).

    """
    fd = os.open(path, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise BagLockedError(f'{path} is still open for writing by another process') from None
        yield
    finally:
        os.close(fd)  # also releases the lock


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
    """rosbags' ``Writer`` with the storages above, its storage file locked and synced.

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
        """Prepare the bag (see ``Writer``).

        Args:
            path: Bag directory to create.
            version: rosbag2 metadata version.
            storage_plugin: mcap or sqlite3.
            flush_period_ns: Longest span of stamps lost on a kill [ns]; None: rosbags'
                own policy (the whole bag for sqlite3, 1 MiB for mcap, nothing synced).

        """
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
        self._lock = os.open(storage.path, os.O_RDONLY)
        fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a new file: never held

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
