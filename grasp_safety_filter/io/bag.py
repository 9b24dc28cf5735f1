"""Writing rosbag2 bags without ROS, with the graph's topics, types and QoS.

:class:`BagRecorder` writes what ``ros2 bag record`` would record from the ROS graph
(rosbag2 metadata version 9, mcap by default or sqlite3, CDR-serialised messages, each
topic's offered QoS from :mod:`grasp_safety_filter.io.topics`), and always leaves a
closed, readable bag: on normal exit, on an exception and on an interrupt. A writer that
dies without closing (SIGKILL, the OOM killer, a power loss) loses less than
:data:`~grasp_safety_filter.io.bag_storage.FLUSH_PERIOD_NS` of stamps
(:mod:`grasp_safety_filter.io.bag_storage`), and
:func:`~grasp_safety_filter.io.bag_recovery.recover_bag` makes its bag readable again.

Interrupts (:mod:`grasp_safety_filter.io.interrupts`): inside ``interrupt_on_signals``,
SIGINT and SIGTERM wait while the recorder writes a message or closes the bag, so the bag
is consistent when the interrupt is raised. A runner therefore records as::

    with interrupt_on_signals(), BagRecorder(path) as bag:
        for ...:
            bag.write(topic, stamp_ns, msg)

Reading is :mod:`grasp_safety_filter.io.bag_reader`'s (:func:`read_bag`, :func:`iter_bag`,
:func:`bag_topics`, :func:`open_bag`, :class:`BagReadError`); its names are importable from
here too.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io.bag_reader import (
    bag_topics,
    BagReadError,
    BagTopic,
    iter_bag,
    open_bag,
    OpenBag,
    read_bag,
)
from grasp_safety_filter.io.bag_storage import DurableWriter, FLUSH_PERIOD_NS
from grasp_safety_filter.io.interrupts import critical_section
from grasp_safety_filter.io.topics import TOPICS, TopicSpec

__all__ = [
    'BAG_VERSION',
    'BagReadError',
    'BagRecorder',
    'BagTopic',
    'OpenBag',
    'Storage',
    'bag_topics',
    'iter_bag',
    'open_bag',
    'read_bag',
]

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
    the bag is closed, with its index and ``metadata.yaml``, also when the block raises
    (an exception or ``KeyboardInterrupt``), so ``AnyReader`` can read everything written
    before. ``rosbags.rosbag2.Writer`` on its own would abort the bag on an exception.
    Without a close (the process killed), the bag keeps all but its last
    ``flush_period_ns`` of stamps, for :func:`~grasp_safety_filter.io.bag_recovery.recover_bag`.
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
            flush_period_ns: Longest span of stamps a kill may lose [ns] (see
                :mod:`~grasp_safety_filter.io.bag_storage`); None: rosbags' own policy.

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
        with critical_section():
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
        """Serialise ``msg`` to CDR and append it to ``topic`` at ``stamp_ns``.

        Args:
            topic: A registered topic.
            stamp_ns: Bag timestamp, integer ns >= 0 (the runner uses the header stamp).
            msg: A message of the topic's type (typestore class).

        Returns:
            The CDR bytes written (what a subscriber of the topic would receive).

        Raises:
            KeyError: Unknown topic.
            TypeError: ``msg`` is of another type than the topic's.
            ValueError: Negative or non-integer ``stamp_ns``.
            RuntimeError: The bag is not open.

        """
        if self._writer is None:
            raise RuntimeError(f'bag {self.path} is not open')
        spec = self.topics.get(topic)
        if spec is None:
            raise KeyError(f'topic {topic!r} is not registered; registered: {list(self.topics)}')
        msgtype = getattr(msg, '__msgtype__', spec.msgtype)
        if msgtype != spec.msgtype:
            raise TypeError(f'topic {topic!r} carries {spec.msgtype}, got a {msgtype}')
        _check_stamp(stamp_ns)
        data = self.typestore.serialize_cdr(msg, spec.msgtype)
        self._append(self._writer, topic, stamp_ns, data)
        return data

    def write_cdr(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Append a message already serialised to CDR (as a subscriber receives it raw).

        Raises:
            KeyError: Unknown topic.
            ValueError: Negative or non-integer ``stamp_ns``.
            RuntimeError: The bag is not open.

        """
        if self._writer is None:
            raise RuntimeError(f'bag {self.path} is not open')
        if topic not in self.topics:
            raise KeyError(f'topic {topic!r} is not registered; registered: {list(self.topics)}')
        _check_stamp(stamp_ns)
        self._append(self._writer, topic, stamp_ns, data)

    def _append(self, writer: DurableWriter, topic: str, stamp_ns: int, data: bytes) -> None:
        """Append checked CDR bytes to a registered topic, interrupts deferred meanwhile."""
        with critical_section():
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
        with critical_section(raise_pending=raise_pending_interrupt):
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


def _check_stamp(stamp_ns: Any) -> None:
    """Raise ValueError unless ``stamp_ns`` is an integer >= 0 (a bag timestamp, ns)."""
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int) or stamp_ns < 0:
        raise ValueError(f'stamp_ns: expected an integer >= 0 ns, got {stamp_ns!r}')
