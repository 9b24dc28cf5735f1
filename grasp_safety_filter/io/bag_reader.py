"""Reading rosbag2 bags without ROS: topics, messages, one-pass or opened once.

:func:`read_bag`, :func:`iter_bag`, :func:`bag_topics` and :func:`open_bag` read any rosbag2
bag (one written by :class:`~grasp_safety_filter.io.bag.BagRecorder` or by
``ros2 bag record``) with ``rosbags``' AnyReader; a missing, foreign, damaged or unrecovered
bag raises :class:`BagReadError` (one line naming the path and the problem).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection, Qos
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io.bag_storage import storage_files


@dataclass(frozen=True)
class BagTopic:
    """A topic as recorded in a bag.

    Attributes:
        name: Topic name.
        msgtype: Message type.
        count: Number of messages.
        offered_qos: Offered QoS profiles of its connections.

    """

    name: str
    msgtype: str
    count: int
    offered_qos: tuple[Qos, ...]


class BagReadError(ValueError):
    """A bag cannot be read: no rosbag2 bag at the path, or a damaged one (names the path)."""


@contextmanager
def _reader(path: Path | str) -> Iterator[AnyReader]:
    """Open a bag; any failure to read it (open or later) becomes :class:`BagReadError`.

    A damaged file fails in whatever layer meets it first (metadata, storage, index,
    compression, CDR), each with its own exception type: all are the same user error.
    """
    path = Path(path)
    _check_bag_directory(path)
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            yield reader
    except BagReadError:
        raise
    except Exception as error:
        raise _read_error(path, error) from error


def _check_bag_directory(path: Path) -> None:
    """Raise :class:`BagReadError` unless ``path`` is a directory that may be a closed bag."""
    if not path.is_dir():
        what = 'does not exist' if not path.exists() else 'is not a directory'
        raise BagReadError(f'{path}: {what}; expected a rosbag2 bag directory')
    if not (path / 'metadata.yaml').exists() and storage_files(path):
        raise BagReadError(
            f'{path}: not a readable rosbag2 bag (no metadata.yaml: its writer did not '
            f'close it); `grasp-analyze --recover {path}` recovers it'
        )


def _read_error(path: Path, error: Exception) -> BagReadError:
    """Return the one-line :class:`BagReadError` of a failure to read the bag at ``path``."""
    if isinstance(error, BagReadError):
        return error
    detail = ' '.join(str(error).split()) or 'no detail'
    return BagReadError(f'{path}: not a readable rosbag2 bag ({type(error).__name__}: {detail})')


def _topics(connections: Iterable[Connection]) -> dict[str, BagTopic]:
    """Return the topics of a bag's connections (see :func:`bag_topics`)."""
    topics: dict[str, BagTopic] = {}
    for connection in connections:
        qos = tuple(getattr(connection.ext, 'offered_qos_profiles', ()))
        known = topics.get(connection.topic)
        if known is None:
            topics[connection.topic] = BagTopic(
                connection.topic, connection.msgtype, connection.msgcount, qos
            )
        else:
            topics[connection.topic] = BagTopic(
                known.name,
                known.msgtype,
                known.count + connection.msgcount,
                known.offered_qos + qos,
            )
    return topics


def bag_topics(path: Path | str) -> dict[str, BagTopic]:
    """Return the topics of a bag with type, message count and offered QoS.

    Raises:
        BagReadError: No bag at ``path``, or it cannot be read.

    """
    with _reader(path) as reader:
        return _topics(reader.connections)


class OpenBag:
    """A bag opened once for several reads (:func:`open_bag`).

    Attributes:
        path: The bag directory.
        topics: Its topics, as :func:`bag_topics` gives them.
    """

    def __init__(self, path: Path, reader: AnyReader) -> None:
        self.path = path
        self.topics = _topics(reader.connections)
        self._reader = reader

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, Any]]:
        """Yield ``(topic, timestamp_ns, message)`` in timestamp order, as :func:`iter_bag`.

        Raises:
            BagReadError: The bag cannot be read part-way through.

        """
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
        BagReadError: No bag at ``path``, or it cannot be read (as :func:`iter_bag`).

    """
    path = Path(path)
    _check_bag_directory(path)
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


def iter_bag(
    path: Path | str, topics: Iterable[str] | None = None
) -> Iterator[tuple[str, int, Any]]:
    """Yield ``(topic, timestamp_ns, message)`` in timestamp order.

    Args:
        path: Bag directory.
        topics: Only these topics (all when None).

    Raises:
        BagReadError: No bag at ``path``, or it cannot be read (also part-way through).

    """
    wanted = None if topics is None else set(topics)
    with _reader(path) as reader:
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not connections:
            return
        for connection, timestamp, rawdata in reader.messages(connections=connections):
            yield connection.topic, timestamp, reader.deserialize(rawdata, connection.msgtype)


def read_bag(
    path: Path | str, topics: Iterable[str] | None = None
) -> dict[str, list[tuple[int, Any]]]:
    """Read a whole bag: ``{topic: [(timestamp_ns, message), ...]}`` in timestamp order.

    Every topic of the bag (or of ``topics``) is a key, also when it has no messages.
    """
    wanted = None if topics is None else set(topics)
    result: dict[str, list[tuple[int, Any]]] = {
        name: [] for name in bag_topics(path) if wanted is None or name in wanted
    }
    for topic, timestamp, msg in iter_bag(path, wanted):
        result[topic].append((timestamp, msg))
    return result
