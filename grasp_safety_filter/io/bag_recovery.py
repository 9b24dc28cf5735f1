"""Recovering a bag whose writer died: no ``metadata.yaml``, an unfinished storage file.

Such a bag (SIGKILL, the OOM killer, a power loss) has an mcap file without its summary and
footer (and maybe a partly written last chunk), or a sqlite3 file with a hot journal of its
uncommitted last transaction; rosbags and ``ros2 bag`` read neither. :func:`recover_bag`
reads every message that reached the disk intact (the mcap records up to the first one cut
off or damaged, each chunk checked record by record; the committed sqlite3 transactions,
after sqlite has rolled back the last one) and writes them with rosbags' ``Writer`` to a new
storage file and ``metadata.yaml``, which then replace the old file. Until then the
original is untouched: an interrupted recovery leaves a ``.recovery`` directory that the
next one removes, and a repeated recovery finds the same messages. A bag whose storage file
a live writer still holds (its ``flock``) is refused.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
import os
from pathlib import Path
import shutil
import sqlite3
import struct
from typing import BinaryIO

from rosbags.interfaces import Connection, MessageDefinition, MessageDefinitionFormat, Qos
from rosbags.rosbag2 import ReaderError, StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import (
    decompress,
    get_qos,
    read_bytes,
    read_exact,
    read_sized,
    read_string,
)
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosbags.typesys.store import Typestore

from grasp_safety_filter.io.bag import bag_topics, BAG_VERSION, BagReadError, require_bag_directory
from grasp_safety_filter.io.bag_storage import (
    BagLockedError,
    storage_files,
    sync_paths,
    writer_lock,
)

STAGING_DIRECTORY = '.recovery'
"""Where the recovered bag is written inside the bag, before it replaces the original."""

_MCAP_MAGIC = b'\x89MCAP0\r\n'
_RECORD = struct.Struct('<BQ')
_CHUNK = struct.Struct('<QQQI')
_MESSAGE = struct.Struct('<HIQQ')
_UINT16 = struct.Struct('<H')
_UINT16_PAIR = struct.Struct('<HH')
_MSGDEF_FORMATS = {'ros2msg': MessageDefinitionFormat.MSG, 'ros2idl': MessageDefinitionFormat.IDL}


@dataclass(frozen=True)
class Recovery:
    """What :func:`recover_bag` did.

    Attributes:
        path: The bag directory.
        problem: What was wrong with it.
        messages: Messages recovered.
        last_stamp_ns: Stamp of the latest one, None when there is none.
        dropped_bytes: mcap: bytes after the last intact record, dropped; sqlite3: None.

    """

    path: Path
    problem: str
    messages: int
    last_stamp_ns: int | None
    dropped_bytes: int | None

    def describe(self) -> str:
        """Return one line: the bag, that it was incomplete, why, and how much was recovered."""
        return f'{self.path}: {self.details()}'

    def details(self) -> str:
        """Return :meth:`describe` without the path (also the bag's custom data)."""
        last = '' if self.last_stamp_ns is None else f' to stamp {self.last_stamp_ns / 1e9:.3f} s'
        dropped = f', dropped {self.dropped_bytes} bytes after them' if self.dropped_bytes else ''
        return (
            f'incomplete bag ({self.problem}), recovered: {self.messages} messages{last}{dropped}'
        )


@dataclass(frozen=True)
class _Topic:
    """A connection found in an unfinished storage file."""

    key: int
    topic: str
    msgtype: str
    msgdef: MessageDefinition
    digest: str
    serialization_format: str
    qos: list[Qos]


_Event = _Topic | tuple[int, int, bytes]  # a connection, or (its key, stamp, data)


@dataclass
class _Scan:
    """What a scan found beside the messages."""

    problems: list[str] = field(default_factory=list)
    dropped_bytes: int | None = None


#: A record that is cut off or not what the format allows: the intact data end there.
_DAMAGE = (ReaderError, UnicodeDecodeError)


class _UnrecoverableError(Exception):
    """Nothing to recover from: the message says why."""


def recover_bag(path: Path | str) -> Recovery | None:
    """Make an incomplete bag readable again (see the module); None if it is complete.

    Raises:
        BagReadError: No bag to recover, one still being written, or a storage file that
            is not mcap or sqlite3 at all.

    """
    path = Path(path)
    require_bag_directory(path)
    if (path / 'metadata.yaml').exists():
        try:
            bag_topics(path)
            return None
        except BagReadError:
            pass  # written out but unreadable: recover what can be
    files = storage_files(path)
    if len(files) != 1:
        what = 'no .mcap or .db3 file' if not files else f'{len(files)} storage files'
        raise BagReadError(f'{path}: cannot recover: {what} in it (expected one)')
    (storage_file,) = files
    scan = _Scan()
    scan.problems.append(
        'unreadable as written' if (path / 'metadata.yaml').exists() else 'no metadata.yaml'
    )
    try:
        with writer_lock(storage_file):
            if storage_file.suffix == '.mcap':
                events = _scan_mcap(storage_file, scan)
                plugin = StoragePlugin.MCAP
            else:
                events = _scan_sqlite3(storage_file, scan)
                plugin = StoragePlugin.SQLITE3
            return _rewrite(path, storage_file, plugin, events, scan)
    except BagLockedError as error:
        raise BagReadError(f'{path}: cannot recover: {error} (still recording?)') from None
    except _UnrecoverableError as error:
        raise BagReadError(f'{path}: cannot recover: {error}') from None
    except Exception as error:
        detail = ' '.join(str(error).split()) or 'no detail'
        raise BagReadError(
            f'{path}: cannot recover: {type(error).__name__}: {detail}'
        ) from error


def _rewrite(
    path: Path, storage_file: Path, plugin: StoragePlugin, events: Iterator[_Event], scan: _Scan
) -> Recovery:
    """Write ``events`` as a new bag beside the old one, then put it in the old one's place."""
    staging_root = path / STAGING_DIRECTORY
    if staging_root.exists():
        shutil.rmtree(staging_root)  # an interrupted recovery's
    staging = staging_root / storage_file.stem
    typestore = get_typestore(Stores.ROS2_JAZZY)
    writer = Writer(staging, version=BAG_VERSION, storage_plugin=plugin)
    writer.open()
    count, last = 0, None
    try:
        connections: dict[int, Connection] = {}
        for event in events:
            if isinstance(event, _Topic):
                if event.key not in connections:
                    connections[event.key] = _add_connection(writer, event, typestore)
                continue
            key, stamp, data = event
            writer.write(connections[key], stamp, data)
            count += 1
            last = stamp if last is None else max(last, stamp)
        recovery = Recovery(
            path, ', '.join(scan.problems), count, last, scan.dropped_bytes
        )
        writer.set_custom_data('recovered', recovery.details())
        writer.close()
    except BaseException:
        writer.abort()
        shutil.rmtree(staging_root, ignore_errors=True)
        raise
    written = staging / f'{staging.name}{storage_file.suffix}'
    sync_paths(written, writer.metapath)
    os.replace(written, storage_file)
    for suffix in ('-journal', '-wal', '-shm'):  # the old database's, never the new one's
        storage_file.with_name(storage_file.name + suffix).unlink(missing_ok=True)
    os.replace(writer.metapath, path / 'metadata.yaml')
    sync_paths(path)
    shutil.rmtree(staging_root)
    return recovery


def _add_connection(writer: Writer, topic: _Topic, typestore: Typestore) -> Connection:
    """Register a found connection, with the type hash rosbag2 puts in metadata.yaml."""
    if topic.msgtype not in typestore.fielddefs:
        if topic.msgdef.format is not MessageDefinitionFormat.MSG:
            raise _UnrecoverableError(
                f'{topic.topic}: type {topic.msgtype} is not a ROS 2 Jazzy type and the '
                'file has no .msg definition of it'
            )
        typestore.register(get_types_from_msg(topic.msgdef.data, topic.msgtype))
    has_msgdef = topic.msgdef.format is not MessageDefinitionFormat.NONE
    return writer.add_connection(
        topic.topic,
        topic.msgtype,
        typestore=typestore,
        msgdef=topic.msgdef.data if has_msgdef else None,
        rihs01=topic.digest or typestore.hash_rihs01(topic.msgtype),
        serialization_format=topic.serialization_format,
        offered_qos_profiles=topic.qos,
    )


# ----------------------------------------------------------------------------------------
# sqlite3


def _scan_sqlite3(storage_file: Path, scan: _Scan) -> Iterator[_Event]:
    """Yield the committed connections and messages of a sqlite3 file."""
    journals = [storage_file.with_name(storage_file.name + s) for s in ('-journal', '-wal')]
    if any(j.exists() for j in journals):
        scan.problems.append('uncommitted sqlite3 transaction rolled back')
    # Opening for writing rolls back a hot journal (what sqlite does for the next writer)
    # and a checkpoint moves committed WAL pages in: rosbags reads the file alone.
    connection = sqlite3.connect(f'file:{storage_file}?mode=rw', uri=True)
    try:
        connection.execute('PRAGMA wal_checkpoint(TRUNCATE)').fetchall()
        connection.execute('SELECT count(*) FROM sqlite_master').fetchall()
    finally:
        connection.close()
    reader = Sqlite3Reader(storage_file)
    reader.open()
    try:
        for c in reader.connections:
            yield _Topic(
                c.id,
                c.topic,
                c.msgtype,
                c.msgdef,
                c.digest,
                c.ext.serialization_format,  # type: ignore[union-attr]
                list(c.ext.offered_qos_profiles),  # type: ignore[union-attr]
            )
        for c, stamp, data in reader.messages(reader.connections):
            yield c.id, stamp, data
    finally:
        reader.close()


# ----------------------------------------------------------------------------------------
# mcap


def _records(buf: bytes, start: int, end: int) -> Iterator[tuple[int, int, int]]:
    """``(opcode, body start, body end)`` of the records in ``buf[start:end]``.

    Stops before a record that is cut off (its length runs past ``end``).
    """
    pos = start
    while end - pos >= _RECORD.size:
        op, length = _RECORD.unpack_from(buf, pos)
        if length > end - pos - _RECORD.size:
            return
        pos += _RECORD.size + length
        yield op, pos - length, pos


def _scan_mcap(storage_file: Path, scan: _Scan) -> Iterator[_Event]:
    """Yield the intact connections and messages of an mcap file, in file order."""
    with storage_file.open('rb') as file:
        magic = file.read(len(_MCAP_MAGIC))
        if magic != _MCAP_MAGIC[: len(magic)]:
            raise _UnrecoverableError(f'{storage_file.name} is not an mcap file')
        yield from _scan_mcap_data(file, os.fstat(file.fileno()).st_size, scan)


def _scan_mcap_data(file: BinaryIO, size: int, scan: _Scan) -> Iterator[_Event]:
    """Yield the records after the magic, to the data end or the first damaged one.

    One record in memory at a time (a chunk at most).
    """
    schemas: dict[int, tuple[str, MessageDefinition]] = {}
    topics: dict[int, _Topic] = {}
    intact = file.tell()
    closed = False
    while size - intact >= _RECORD.size:
        op, length = _RECORD.unpack(file.read(_RECORD.size))
        end = intact + _RECORD.size + length
        if end > size or not 0x01 <= op <= 0x0F:  # cut off, or not a record: garbage
            break
        if op in (0x0F, 0x02):  # data end, footer: what follows is the summary
            closed = True
            break
        if 0x03 <= op <= 0x06:
            body = file.read(length)
            try:
                if op == 0x06:
                    events = _chunk(body, schemas, topics)
                else:
                    events = list(_record(op, body, schemas, topics))
            except _DAMAGE:
                break
            yield from events
        else:  # header, indexes, attachments, metadata
            file.seek(end)
        intact = end
    if not closed:
        scan.problems.append('mcap file not closed')
        scan.dropped_bytes = size - intact


def _chunk(
    body: bytes,
    schemas: dict[int, tuple[str, MessageDefinition]],
    topics: dict[int, _Topic],
) -> list[_Event]:
    """Return a chunk's records, all checked: a damaged chunk contributes nothing."""
    record = BytesIO(body)
    start_time, end_time, raw_size, crc = _CHUNK.unpack(read_exact(record, _CHUNK.size))
    compression = read_string(record)
    data = read_sized(record)
    try:
        raw = decompress(data, compression, raw_size, crc)
    except Exception:  # the codecs' own error types: a damaged chunk all the same
        raise ReaderError from None
    events: list[_Event] = []
    pos = 0
    for op, start, stop in _records(raw, 0, len(raw)):
        if op not in (0x03, 0x04, 0x05):
            raise ReaderError
        for event in _record(op, raw[start:stop], schemas, topics):
            if not isinstance(event, _Topic) and not start_time <= event[1] <= end_time:
                raise ReaderError
            events.append(event)
        pos = stop
    if pos != len(raw):
        raise ReaderError
    return events


def _record(
    op: int,
    body: bytes,
    schemas: dict[int, tuple[str, MessageDefinition]],
    topics: dict[int, _Topic],
) -> Iterator[_Event]:
    """Yield what a record adds: a schema (registered), a connection or a message."""
    record = BytesIO(body)
    if op == 0x05:
        key, _, stamp, _ = _MESSAGE.unpack(read_exact(record, _MESSAGE.size))
        if key not in topics:
            raise ReaderError
        yield key, stamp, record.read()
    elif op == 0x03:
        (key,) = _UINT16.unpack(read_exact(record, 2))
        name, encoding = read_string(record), read_string(record)
        fmt = _MSGDEF_FORMATS.get(encoding, MessageDefinitionFormat.NONE)
        schemas[key] = (name, MessageDefinition(fmt, read_string(record)))
    else:
        key, schema = _UINT16_PAIR.unpack(read_exact(record, 4))
        topic, encoding = read_string(record), read_string(record)
        metadata = read_bytes(record)
        if schema not in schemas:
            raise ReaderError
        if key not in topics:
            try:
                qos = get_qos(metadata)
            except Exception:  # rosbags' and the YAML parser's errors alike
                raise ReaderError from None
            msgtype, msgdef = schemas[schema]
            topics[key] = _Topic(key, topic, msgtype, msgdef, '', encoding, qos)
            yield topics[key]
