"""rosbag2 bags without ROS: :class:`BagRecorder` writes them, :func:`open_bag` reads them.

The recorder writes what ``ros2 bag record`` would record from the ROS graph (rosbag2
metadata version 9, mcap by default or sqlite3, CDR, each topic's offered QoS from
:mod:`grasp_safety_filter.io.topics`) and always leaves a closed, readable bag: on normal
exit, on an exception and on an interrupt. A writer that dies without closing (SIGKILL, the
OOM killer, a power loss) loses less than
:data:`~grasp_safety_filter.io.bag_storage.FLUSH_PERIOD_NS` of stamps, and
:func:`~grasp_safety_filter.io.bag_recovery.recover_bag` makes its bag readable again.
Inside ``interrupt_on_signals`` (:mod:`grasp_safety_filter.io.interrupts`), SIGINT and
SIGTERM wait while the recorder writes a message or closes the bag, so the bag is
consistent when the interrupt is raised::

    with interrupt_on_signals(), BagRecorder(path) as bag:
        for ...:
            bag.write(topic, stamp_ns, msg)

The readers take any rosbag2 bag (the recorder's or ``ros2 bag record``'s) through rosbags'
``AnyReader``; a missing, foreign, damaged or unrecovered bag raises :class:`BagReadError`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io.bag_storage import DurableWriter, FLUSH_PERIOD_NS, needs_recovery
from grasp_safety_filter.io.interrupts import deferred_interrupts
from grasp_safety_filter.io.topics import TOPICS, TopicSpec

Storage = Literal['mcap', 'sqlite3']

BAG_VERSION = 9
"""rosbag2 metadata version written (that of ROS 2 Jazzy)."""

_STORAGE_PLUGINS: dict[str, StoragePlugin] = {
    'mcap': StoragePlugin.MCAP,
    'sqlite3': StoragePlugin.SQLITE3,
}


class BagRecorder:
    """A rosbag2 bag of the package's topics, closed whatever happens.

    Use as a context manager (or call :meth:`open` and :meth:`close` in ``try/finally``):
    the bag is closed, with its index and ``metadata.yaml``, also when the block raises, so
    ``AnyReader`` reads everything written before (``rosbags.rosbag2.Writer`` on its own
    would abort the bag on an exception).
    """

    def __init__(
        self,
        path: Path | str,
        storage: Storage = 'mcap',
        topics: Iterable[TopicSpec] = TOPICS,
        typestore: Any = None,
        flush_period_ns: int | None = FLUSH_PERIOD_NS,
    ) -> None:
        """Prepare a bag; nothing is created before :meth:`open`.

        Args:
            path: Bag directory to create (must not exist).
            storage: ``"mcap"`` (the Jazzy default) or ``"sqlite3"``.
            topics: Topics to register, with their types and offered QoS.
            typestore: rosbags typestore for serialisation (default ROS2_JAZZY).
            flush_period_ns: Longest span of stamps a kill may lose [ns]
                (:mod:`~grasp_safety_filter.io.bag_storage`); None: rosbags' own policy.

        """
        if storage not in _STORAGE_PLUGINS:
            raise ValueError(
                f'storage: expected one of {sorted(_STORAGE_PLUGINS)}, got {storage!r}'
            )
        self.path = Path(path)
        self.storage = storage
        self.topics: dict[str, TopicSpec] = {}
        for spec in topics:
            if spec.name in self.topics:
                raise ValueError(f'topics: {spec.name!r} is listed twice')
            self.topics[spec.name] = spec
        self.typestore = get_typestore(Stores.ROS2_JAZZY) if typestore is None else typestore
        self.counts: dict[str, int] = dict.fromkeys(self.topics, 0)
        self.flush_period_ns = flush_period_ns
        self._writer: DurableWriter | None = None
        self._connections: dict[str, Connection] = {}

    @property
    def is_open(self) -> bool:
        """Whether the bag is open for writing."""
        return self._writer is not None

    def open(self) -> None:
        """Create the bag directory and register every topic.

        Raises:
            rosbags.rosbag2.WriterError: ``path`` exists already.

        """
        if self._writer is not None:
            raise RuntimeError(f'bag {self.path} is already open')
        writer = DurableWriter(
            self.path,
            version=BAG_VERSION,
            storage_plugin=_STORAGE_PLUGINS[self.storage],
            flush_period_ns=self.flush_period_ns,
        )
        with deferred_interrupts():
            writer.open()
            try:
                for spec in self.topics.values():
                    self._connections[spec.name] = writer.add_connection(
                        spec.name,
                        spec.msgtype,
                        typestore=self.typestore,
                        serialization_format='cdr',
                        offered_qos_profiles=[spec.qos.to_rosbags()],
                    )
            except BaseException:
                writer.abort()
                raise
            self._writer = writer

    def write(self, topic: str, stamp_ns: int, msg: Any) -> bytes:
        """Serialise ``msg`` (the topic's typestore class) and append it at ``stamp_ns``.

        Returns:
            The CDR bytes written (what a subscriber of the topic would receive).

        Raises:
            TypeError: ``msg`` is of another type than the topic's.
            KeyError, ValueError, RuntimeError: As :meth:`write_cdr`.

        """
        writer, spec = self._checked(topic, stamp_ns)
        msgtype = getattr(msg, '__msgtype__', spec.msgtype)
        if msgtype != spec.msgtype:
            raise TypeError(f'topic {topic!r} carries {spec.msgtype}, got a {msgtype}')
        data = self.typestore.serialize_cdr(msg, spec.msgtype)
        self._append(writer, topic, stamp_ns, data)
        return data

    def write_cdr(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Append a message already serialised to CDR (as a subscriber receives it raw).

        Raises:
            KeyError: Unknown topic.
            ValueError: ``stamp_ns`` is not an integer >= 0 (the bag timestamp, ns).
            RuntimeError: The bag is not open.

        """
        writer, _ = self._checked(topic, stamp_ns)
        self._append(writer, topic, stamp_ns, data)

    def _checked(self, topic: str, stamp_ns: Any) -> tuple[DurableWriter, TopicSpec]:
        if self._writer is None:
            raise RuntimeError(f'bag {self.path} is not open')
        spec = self.topics.get(topic)
        if spec is None:
            raise KeyError(f'topic {topic!r} is not registered; registered: {list(self.topics)}')
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int) or stamp_ns < 0:
            raise ValueError(f'stamp_ns: expected an integer >= 0 ns, got {stamp_ns!r}')
        return self._writer, spec

    def _append(self, writer: DurableWriter, topic: str, stamp_ns: int, data: bytes) -> None:
        with deferred_interrupts():
            writer.write(self._connections[topic], stamp_ns, data)
            self.counts[topic] += 1

    def set_custom_data(self, key: str, value: str) -> None:
        """Store a string in the bag's ``metadata.yaml`` ``custom_data`` (before closing)."""
        if self._writer is None:
            raise RuntimeError(f'bag {self.path} is not open')
        self._writer.set_custom_data(key, value)

    def close(self, raise_pending_interrupt: bool = True) -> None:
        """Write the index and ``metadata.yaml``; no-op if not open.

        Args:
            raise_pending_interrupt: Raise an interrupt that arrived while closing, after
                closing (False when already unwinding from an exception).

        """
        writer, self._writer = self._writer, None
        if writer is None:
            return
        with deferred_interrupts(raise_pending=raise_pending_interrupt):
            try:
                writer.close()
            except BaseException:
                writer.abort()
                raise

    def __enter__(self) -> BagRecorder:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc_value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close(raise_pending_interrupt=exc_type is None)


# ----------------------------------------------------------------------------------------
# Reading


@dataclass(frozen=True)
class BagTopic:
    """A topic as recorded in a bag: its type, message count and offered QoS profiles."""

    name: str
    msgtype: str
    count: int
    offered_qos: tuple[Qos, ...]


class BagReadError(ValueError):
    """A bag cannot be read: no rosbag2 bag at the path, or a damaged one (names the path)."""


def require_bag_directory(path: Path) -> None:
    """Raise :class:`BagReadError` unless ``path`` is a directory."""
    if not path.is_dir():
        what = 'does not exist' if not path.exists() else 'is not a directory'
        raise BagReadError(f'{path}: {what}; expected a rosbag2 bag directory')


def _read_error(path: Path, error: Exception) -> BagReadError:
    """Return the one-line :class:`BagReadError` of a failure to read the bag at ``path``.

    A damaged file fails in whatever layer meets it first (metadata, storage, index,
    compression, CDR), each with its own exception type: all are the same user error.
    """
    if isinstance(error, BagReadError):
        return error
    detail = ' '.join(str(error).split()) or 'no detail'
    return BagReadError(f'{path}: not a readable rosbag2 bag ({type(error).__name__}: {detail})')


class OpenBag:
    """A bag opened once for several reads (:func:`open_bag`).

    Attributes:
        path: The bag directory.
        topics: Its topics, as :func:`bag_topics` gives them.
    """

    def __init__(self, path: Path, reader: AnyReader) -> None:
        self.path = path
        self.topics: dict[str, BagTopic] = {}
        for c in reader.connections:
            qos = tuple(getattr(c.ext, 'offered_qos_profiles', ()))
            known = self.topics.get(c.topic, BagTopic(c.topic, c.msgtype, 0, ()))
            self.topics[c.topic] = BagTopic(
                c.topic, known.msgtype, known.count + c.msgcount, known.offered_qos + qos
            )
        self._reader = reader

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, Any]]:
        """Yield ``(topic, timestamp_ns, message)`` in timestamp order, as :func:`iter_bag`."""
        wanted = None if topics is None else set(topics)
        reader = self._reader
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not connections:
            return
        try:
            for connection, timestamp, rawdata in reader.messages(connections=connections):
                yield connection.topic, timestamp, reader.deserialize(rawdata, connection.msgtype)
        except Exception as error:
            raise _read_error(self.path, error) from error


@contextmanager
def open_bag(path: Path | str) -> Iterator[OpenBag]:
    """Open a bag once for its topics and several passes over its messages.

    Only reading the bag raises :class:`BagReadError`; what the block raises is its own.

    Raises:
        BagReadError: No bag at ``path``, or it cannot be read (also part-way through).

    """
    path = Path(path)
    require_bag_directory(path)
    if needs_recovery(path):
        raise BagReadError(
            f'{path}: not a readable rosbag2 bag (no metadata.yaml: its writer did not '
            f'close it); `grasp-analyze --recover {path}` recovers it'
        )
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
        bag = OpenBag(path, reader)
    except Exception as error:
        raise _read_error(path, error) from error
    try:
        yield bag
    finally:
        try:
            reader.close()
        except Exception as error:
            raise _read_error(path, error) from error


def bag_topics(path: Path | str) -> dict[str, BagTopic]:
    """Return the topics of a bag with type, message count and offered QoS (see open_bag)."""
    with open_bag(path) as bag:
        return bag.topics


def iter_bag(
    path: Path | str, topics: Iterable[str] | None = None
) -> Iterator[tuple[str, int, Any]]:
    """Yield ``(topic, timestamp_ns, message)`` of ``topics`` (None: all) in timestamp order.

    Raises:
        BagReadError: As :func:`open_bag`.

    """
    with open_bag(path) as bag:
        yield from bag.messages(topics)


def read_bag(
    path: Path | str, topics: Iterable[str] | None = None
) -> dict[str, list[tuple[int, Any]]]:
    """Read a whole bag: ``{topic: [(timestamp_ns, message), ...]}`` in timestamp order.

    Every topic of the bag (or of ``topics``) is a key, also when it has no messages.
    """
    wanted = None if topics is None else set(topics)
    with open_bag(path) as bag:
        result: dict[str, list[tuple[int, Any]]] = {
            name: [] for name in bag.topics if wanted is None or name in wanted
        }
        for topic, timestamp, msg in bag.messages(wanted):
            result[topic].append((timestamp, msg))
    return result
