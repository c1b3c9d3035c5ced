"""sensor_msgs/JointState in rosbag2 MCAP bags, through rosbags (pure Python, no ROS install needed).

Bags are written as ``ros2 bag record -s mcap`` writes them (a folder with ``metadata.yaml`` and one
``.mcap`` file, CDR messages with the Kilted type definitions), so ``ros2 bag play``/``info`` accept
them. Reading takes a bag folder or a bare ``.mcap`` file.
"""

from __future__ import annotations

import mmap
import os
import re
import struct
from collections.abc import Iterable, Sequence
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


def _damage_errors() -> tuple[type[BaseException], ...]:
    """What rosbags' readers (0.11) raise on a damaged file, found by reading damaged and fuzzed bags
    (test/test_bags_damaged.py): its own ReaderError; struct.error where a field is cut short;
    TypeError from ``ord()`` of the empty read at a file's end; OverflowError and MemoryError where a
    damaged length is beyond what a read or a seek takes; ValueError (UnicodeDecodeError in a name, a
    negative seek); KeyError for an unknown schema encoding; the decompressors' own errors."""
    import struct

    from backports.zstd import ZstdError
    from lz4.block import LZ4BlockError
    from rosbags.rosbag2 import ReaderError

    return (ReaderError, OSError, struct.error, TypeError, OverflowError, MemoryError, ValueError,
            KeyError, ZstdError, LZ4BlockError)


class DamagedBag(MotionStyleError):
    """A bag (or its index) that cannot be read whole; the message says where and why."""


def _reader(path: Path):
    from rosbags.rosbag2 import Reader

    if not path.exists():
        raise MotionStyleError(f"{path}: no such bag folder or .mcap file")
    if path.is_file() and path.stat().st_size == 0:
        raise DamagedBag(f"{path}: damaged bag (an empty file)")
    try:
        reader = Reader(path)
        reader.open()
    except _damage_errors() as exc:
        raise DamagedBag(f"{path}: not a readable rosbag2 bag ({_why(exc)})") from None
    return reader


def _why(exc: BaseException) -> str:
    """An exception from a damaged file as a reason on one line."""
    text = " ".join(str(exc).split())
    if isinstance(exc, (TypeError, OverflowError, MemoryError)) or not text:
        text = f"a damaged record ({type(exc).__name__}{': ' + text if text else ''})"
    return text


def check_joint_state(store, data: bytes):
    """``(message, "")`` if ``data`` is a CDR sensor_msgs/JointState this package can use, else
    ``(None, reason)``: it deserialises, has a position per name, a velocity and an effort per name
    or none, and every value is finite."""
    from rosbags.serde import SerdeError

    try:
        msg = store.deserialize_cdr(data, JOINT_STATE)
    except (SerdeError, MemoryError) as exc:  # MemoryError: a damaged sequence length
        return None, f"not a JointState ({_why(exc)})"
    n = len(msg.name)
    if len(msg.position) != n:
        return None, f"{n} names but {len(msg.position)} positions"
    for field in ("velocity", "effort"):
        if len(getattr(msg, field)) not in (0, n):
            return None, f"{n} names but {len(getattr(msg, field))} {field} values"
    for field in ("position", "velocity", "effort"):
        if not np.all(np.isfinite(getattr(msg, field))):
            return None, f"a non-finite {field}"
    return msg, ""


@dataclass
class BagContents:
    """What a bag reader got: ``messages`` as ``(topic, log_time_ns, cdr, message)``, each a usable
    JointState, in log-time order (``message`` the deserialised one if asked for, else None: a
    player needs only the bytes, and a long bag's messages take several times their size). ``damage`` is empty for an intact bag; else why it is damaged,
    and ``skipped`` how many of its JointState messages were left out (None: not known, when neither
    metadata.yaml nor the file's summary says how many there were)."""

    messages: list[tuple[str, int, bytes, object]]
    damage: str = ""
    skipped: int | None = 0


def read_checked(path: str | Path, topics: Sequence[str] | None = None,
                 skip_damaged: bool = False, decoded: bool = False) -> BagContents:
    """Every JointState message of the bag, each deserialised and checked before anything uses it.

    A damaged bag (the file cut short or overwritten, an index that lists messages the file lacks,
    a message that is not a usable JointState) raises :class:`DamagedBag` in one line; with
    ``skip_damaged`` its readable messages are returned instead (an MCAP bag is scanned record by
    record past the damage), with the reason and the count left out. ``decoded``: keep each
    deserialised message.
    """
    path = Path(path)
    try:
        return BagContents(_read_whole(path, topics, decoded))
    except DamagedBag as exc:
        if not skip_damaged:
            raise
        return _salvage(path, topics, str(exc).removeprefix(f"{path}: "), decoded)


def _wanted(topics: Sequence[str] | None):
    wanted = None if topics is None else {"/" + t.lstrip("/") for t in topics}
    return lambda topic, msgtype: msgtype == JOINT_STATE and (wanted is None
                                                              or "/" + topic.lstrip("/") in wanted)


def _read_whole(path: Path, topics: Sequence[str] | None,
                decoded: bool) -> list[tuple[str, int, bytes, object]]:
    store = typestore()
    reader = _reader(path)
    wanted = _wanted(topics)
    out = []
    try:
        conns = [c for c in reader.connections if wanted(c.topic, c.msgtype)]
        if not conns:
            found = sorted(f"{c.topic} ({c.msgtype})" for c in reader.connections)
            raise MotionStyleError(f"{path}: no {JOINT_STATE} messages"
                                   f"{'' if topics is None else ' on ' + ', '.join(topics)}; "
                                   f"the bag has: {', '.join(found) or 'nothing'}")
        listed = sum(c.msgcount for c in conns)
        try:
            for conn, timestamp, data in reader.messages(connections=conns):
                data = bytes(data)
                msg, why = check_joint_state(store, data)
                if msg is None:
                    raise DamagedBag(f"{path}: damaged bag (message {len(out) + 1} on {conn.topic}: "
                                     f"{why})")
                out.append((conn.topic, timestamp, data, msg if decoded else None))
        except _damage_errors() as exc:
            raise DamagedBag(f"{path}: damaged bag ({_why(exc)})") from None
    finally:
        try:
            reader.close()
        except _damage_errors():
            pass
    if listed and len(out) != listed:
        raise DamagedBag(f"{path}: damaged bag (its index lists {listed} JointState messages, "
                         f"{len(out)} could be read)")
    return out


def read_raw(path: str | Path, topics: Sequence[str] | None = None) -> list[tuple[str, int, bytes]]:
    """``(topic, log_time_ns, cdr)`` of every JointState message in log-time order, each checked
    (:func:`read_checked`); a damaged bag raises :class:`DamagedBag`.

    ``topics`` restricts the topics (names as recorded, with or without the leading slash).
    """
    return [(t, log, data) for t, log, data, _ in read_checked(path, topics).messages]


def read_joint_states(path: str | Path, topics: Sequence[str] | None = None) -> list[JointStateRecord]:
    """Every JointState in the bag (all topics unless ``topics`` is given), in log-time order; a
    damaged bag raises :class:`DamagedBag`."""
    records = []
    for _, log_time, _, msg in read_checked(path, topics, decoded=True).messages:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        records.append(JointStateRecord(
            stamp, list(msg.name), np.array(msg.position, dtype=np.float64),
            np.array(msg.velocity, dtype=np.float64) if len(msg.velocity) else None,
            msg.header.frame_id, log_time))
    return records


# Salvage: an MCAP file read record by record, past damage.
# MCAP records are an opcode byte, a little-endian uint64 length and that many bytes
# (https://mcap.dev/spec); a chunk (0x06) holds schema (0x03), channel (0x04) and message (0x05)
# records, compressed or not.
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_MAGIC = b"\x89MCAP0\r\n"
_CDR = (b"\x00\x01\x00\x00", b"\x00\x00\x00\x00")
_CANDIDATE = re.compile(b"[\x04-\x06]")


class _Scan:
    """The records an MCAP file still holds: channels, messages, the summary's count, damage."""

    def __init__(self) -> None:
        self.channels: dict[int, tuple[str, str]] = {}  # id -> (topic, schema name)
        self.schemas: dict[int, str] = {}
        self.messages: list[tuple[int, int, bytes]] = []  # (channel, log time, cdr)
        self.listed: dict[int, int] | None = None  # the statistics record's count per channel
        self.damaged_bytes = 0

    def _string(self, buf, pos: int, end: int) -> tuple[str, int]:
        n = _U32.unpack_from(buf, pos)[0]
        if pos + 4 + n > end:
            raise ValueError("string past its record")
        return bytes(buf[pos + 4:pos + 4 + n]).decode(), pos + 4 + n

    def _record(self, buf, op: int, pos: int, end: int, top: bool) -> bool:
        """Take the record ``op`` with body ``buf[pos:end]``; False if it is not a valid one."""
        try:
            if op == 0x05:
                if end - pos < 26 or bytes(buf[pos + 22:pos + 26]) not in _CDR:
                    return False
                channel = _U16.unpack_from(buf, pos)[0]
                log_time = _U64.unpack_from(buf, pos + 6)[0]
                self.messages.append((channel, log_time, bytes(buf[pos + 22:end])))
            elif op == 0x04:
                cid, sid = _U16.unpack_from(buf, pos)[0], _U16.unpack_from(buf, pos + 2)[0]
                topic, p = self._string(buf, pos + 4, end)
                _, p = self._string(buf, p, end)  # message encoding
                _, p = self._string(buf, p, end)  # metadata (a map's bytes, sized alike)
                if p != end:
                    return False
                self.channels[cid] = (topic, sid)
            elif op == 0x03:
                sid = _U16.unpack_from(buf, pos)[0]
                name, _ = self._string(buf, pos + 2, end)
                self.schemas[sid] = name
            elif op == 0x06 and top:
                return self._chunk(buf, pos, end)
            elif op == 0x0B and top:  # statistics: the count of each channel's messages
                n = _U32.unpack_from(buf, pos + 42)[0]
                if pos + 46 + n > end:
                    return False
                pairs = buf[pos + 46:pos + 46 + n - n % 10]
                self.listed = dict(struct.iter_unpack("<HQ", pairs))
            elif not 0x01 <= op <= 0x0F:
                return False
        except (struct.error, ValueError):  # a field past the record's end; a name not UTF-8
            return False
        return True

    def _chunk(self, buf, pos: int, end: int) -> bool:
        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

        size = _U64.unpack_from(buf, pos + 16)[0]
        compression, p = self._string(buf, pos + 28, len(buf))
        if compression not in DECOMPRESSORS or p + 8 > len(buf):
            return False
        stored = _U64.unpack_from(buf, p)[0]
        if not self._consistent(compression, p + 8 + stored, end, len(buf)):
            return False
        data = buf[p + 8:min(p + 8 + stored, len(buf))]
        if compression:
            try:
                data = DECOMPRESSORS[compression](bytes(data), size)
            except _damage_errors():
                self.damaged_bytes += len(data)
                return True
        self.walk(memoryview(data), 0, len(data), top=False)
        return True

    def walk(self, buf, pos: int, end: int, top: bool) -> None:
        """Every valid record in ``buf[pos:end]``; from a record that is not, on to the next that is."""
        while pos + 9 <= end:
            op, length = buf[pos], _U64.unpack_from(buf, pos + 1)[0]
            stop = pos + 9 + length
            # a chunk cut short by the file's end still holds messages
            fits = stop <= end or (top and op == 0x06)
            if fits and self._record(buf, op, pos + 9, stop, top):
                if stop >= end:
                    return
                pos = stop
                continue
            bad = pos
            pos = self._next(buf, pos + 1, end, top)
            self.damaged_bytes += pos - bad

    def _next(self, buf, pos: int, end: int, top: bool) -> int:
        """The start of the next record after damage that reads as a channel, message or chunk."""
        for m in _CANDIDATE.finditer(buf, pos, end):
            p = m.start()
            if p + 9 > end:
                break
            op, length = buf[p], _U64.unpack_from(buf, p + 1)[0]
            if op == 0x06 and not top:
                continue
            stop = p + 9 + length
            if ((stop <= end or (top and op == 0x06)) and length >= 4
                    and self._probe(buf, op, p + 9, stop, top)):
                return p
        return end

    def _probe(self, buf, op: int, pos: int, end: int, top: bool) -> bool:
        """Whether the record would be taken, without taking it."""
        if op == 0x06:
            return self._chunk_header_ok(buf, pos, end)
        return _Scan()._record(buf, op, pos, end, top)

    def _chunk_header_ok(self, buf, pos: int, end: int) -> bool:
        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

        try:
            compression, p = self._string(buf, pos + 28, len(buf))
            stored = _U64.unpack_from(buf, p)[0]
        except (struct.error, ValueError):
            return False
        return compression in DECOMPRESSORS and self._consistent(compression, p + 8 + stored, end,
                                                                 len(buf))

    @staticmethod
    def _consistent(compression: str, data_end: int, end: int, size: int) -> bool:
        """Whether a chunk's data ends where its record does; past the file's end only for an
        uncompressed chunk (a file cut short: its first records still read)."""
        return data_end == end and (end <= size or compression == "")


def _bag_files(path: Path) -> tuple[list[Path], int | None, dict[str, int]]:
    """The MCAP files of a bag and, from its metadata.yaml where that still reads, how many
    messages it lists in all and per topic."""
    if path.is_file():
        return [path], None, {}
    listed: dict[str, int] = {}
    files = sorted(path.glob("*.mcap"))
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    try:
        info = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        files = [path / str(f) for f in info["relative_file_paths"]] or files
        for t in info["topics_with_message_count"]:
            meta = t["topic_metadata"]
            if meta["type"] == JOINT_STATE:
                listed[str(meta["name"])] = int(t["message_count"])
        total = sum(listed.values())
    except (OSError, YAMLError, KeyError, TypeError, ValueError):  # metadata.yaml missing or damaged
        return files, None, {}
    return files, total, listed


def _salvage(path: Path, topics: Sequence[str] | None, damage: str, decoded: bool) -> BagContents:
    store = typestore()
    wanted = _wanted(topics)
    files, _, listed_by_topic = _bag_files(path)
    messages: list[tuple[str, int, bytes, object]] = []
    undecodable = 0
    listed_file: int | None = 0  # from the files' statistics records
    for file in files:
        scan = _Scan()
        try:
            with open(file, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                # mapped, not read: a long bag is gigabytes; the scan copies out only the messages
                buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
        except OSError as exc:
            raise MotionStyleError(f"{file}: cannot read ({exc.strerror or exc})") from None
        if buf[:len(_MAGIC)] == _MAGIC:
            view = memoryview(buf)
            try:
                scan.walk(view, len(_MAGIC), len(buf), top=True)
            finally:
                view.release()
        schema_of = scan.schemas
        for channel, log_time, data in scan.messages:
            if channel not in scan.channels:
                undecodable += 1
                continue
            topic, sid = scan.channels[channel]
            if not wanted(topic, schema_of.get(sid, JOINT_STATE)):
                continue
            msg, _ = check_joint_state(store, data)
            if msg is None:
                undecodable += 1
            else:
                messages.append((topic, log_time, data, msg if decoded else None))
        if scan.listed is None or listed_file is None:
            listed_file = None
        else:
            listed_file += sum(n for cid, n in scan.listed.items() if cid in scan.channels and wanted(
                scan.channels[cid][0], schema_of.get(scan.channels[cid][1], JOINT_STATE)))
    messages.sort(key=lambda m: m[1])
    listed = (sum(n for t, n in listed_by_topic.items() if wanted(t, JOINT_STATE)) if listed_by_topic
              else listed_file)
    skipped = None if listed is None else max(listed - len(messages), undecodable)
    if not messages:
        raise DamagedBag(f"{path}: {damage}; no JointState message in it can be read")
    return BagContents(messages, damage, skipped)
