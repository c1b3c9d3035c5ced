"""sensor_msgs/JointState in rosbag2 MCAP bags, through rosbags (pure Python, no ROS install needed).

Bags are written as ``ros2 bag record -s mcap`` writes them (a folder with ``metadata.yaml`` and one
``.mcap`` file, CDR messages with the Kilted type definitions), so ``ros2 bag play``/``info`` accept
them. Reading takes a bag folder or a bare ``.mcap`` file.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError

JOINT_STATE = "sensor_msgs/msg/JointState"


def typestore():
    """The message definitions of the ROS 2 distribution the package targets (Kilted)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_KILTED)


@dataclass
class JointStateRecord:
    """One JointState as stored: ``stamp_ns`` is header.stamp, ``log_time_ns`` when it was recorded."""

    stamp_ns: int
    names: list[str]
    positions: np.ndarray
    velocities: np.ndarray | None = None
    frame_id: str = ""
    log_time_ns: int | None = None  # defaults to stamp_ns when writing


class BagWriter:
    """An MCAP rosbag2 bag open for writing; a context manager that closes (finalises) the bag.

    ``write_raw`` stores already-serialised CDR (what a raw rclpy subscription hands over), so a
    recorder never converts messages.
    """

    def __init__(self, path: str | Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

        self.path = Path(path)
        if self.path.exists():
            raise MotionStyleError(f"{self.path}: already exists; choose a new bag folder")
        self._store = typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise MotionStyleError(f"{self.path}: cannot create bag ({exc})") from None
        self._connections: dict[str, object] = {}
        self.count = 0

    def _connection(self, topic: str, msgtype: str):
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=self._store)
        return self._connections[topic]

    def write_raw(self, topic: str, log_time_ns: int, data: bytes, msgtype: str = JOINT_STATE) -> None:
        self._writer.write(self._connection(topic, msgtype), int(log_time_ns), data)
        self.count += 1

    def write(self, topic: str, record: JointStateRecord) -> None:
        types = self._store.types
        sec, nsec = divmod(int(record.stamp_ns), 1_000_000_000)
        header = types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=record.frame_id)
        velocity = np.zeros(0) if record.velocities is None else record.velocities
        msg = types[JOINT_STATE](
            header=header, name=list(record.names),
            position=np.asarray(record.positions, dtype=np.float64),
            velocity=np.asarray(velocity, dtype=np.float64), effort=np.zeros(0))
        log_time = record.stamp_ns if record.log_time_ns is None else record.log_time_ns
        self.write_raw(topic, log_time, bytes(self._store.serialize_cdr(msg, JOINT_STATE)))

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_joint_states(path: str | Path, records: Iterable[JointStateRecord],
                       topic: str = "joint_states") -> int:
    """Write ``records`` on ``topic`` to a new MCAP bag folder; returns how many were written."""
    with BagWriter(path) as writer:
        for record in records:
            writer.write(topic, record)
        return writer.count


def _reader(path: Path):
    from rosbags.rosbag2 import Reader, ReaderError

    if not path.exists():
        raise MotionStyleError(f"{path}: no such bag folder or .mcap file")
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError) as exc:
        raise MotionStyleError(f"{path}: not a readable rosbag2 bag ({exc})") from None
    return reader


def read_raw(path: str | Path, topics: Sequence[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
    """``(topic, log_time_ns, cdr)`` of every JointState message in log-time order.

    ``topics`` restricts the topics (names as recorded, with or without the leading slash).
    """
    path = Path(path)
    reader = _reader(path)
    try:
        wanted = None if topics is None else {"/" + t.lstrip("/") for t in topics}
        conns = [c for c in reader.connections if c.msgtype == JOINT_STATE
                 and (wanted is None or "/" + c.topic.lstrip("/") in wanted)]
        if not conns:
            found = sorted(f"{c.topic} ({c.msgtype})" for c in reader.connections)
            raise MotionStyleError(f"{path}: no {JOINT_STATE} messages"
                                   f"{'' if topics is None else ' on ' + ', '.join(topics)}; "
                                   f"the bag has: {', '.join(found) or 'nothing'}")
        for conn, timestamp, data in reader.messages(connections=conns):
            yield conn.topic, timestamp, bytes(data)
    finally:
        reader.close()


def read_joint_states(path: str | Path, topics: Sequence[str] | None = None) -> list[JointStateRecord]:
    """Every JointState in the bag (all topics unless ``topics`` is given), in log-time order."""
    store = typestore()
    records = []
    for _, log_time, data in read_raw(path, topics):
        msg = store.deserialize_cdr(data, JOINT_STATE)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        records.append(JointStateRecord(
            stamp, list(msg.name), np.array(msg.position, dtype=np.float64),
            np.array(msg.velocity, dtype=np.float64) if len(msg.velocity) else None,
            msg.header.frame_id, log_time))
    return records
