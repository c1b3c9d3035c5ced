"""VMC over UDP: a sender, and a receiver that stays live under any burst."""

from __future__ import annotations

import queue
import socket
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import replace

from pythonosc import osc_bundle, osc_message

from motion_style_ros.io.vmc.assembly import VmcFrameAssembler
from motion_style_ros.io.vmc.osc import Packet, frame_bundle
from motion_style_ros.io.vmc.protocol import VmcFrame

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 39539  # a marionette listens here (the bridge, for the performer app)
DEFAULT_SEND_PORT = 39540  # where the bridge sends: a marionette on the same host, by convention
RECEIVE_BUFFER = 4 * 1024 * 1024  # bytes of socket buffer asked for (the kernel may cap it: rmem_max)
# A datagram that waited longer than this to be parsed is dropped: a live pose that old is stale.
MAX_AGE_S = 0.25
MAX_QUEUED_BYTES = 16 * 1024 * 1024  # datagrams read but not parsed, at most (then the newest are dropped)


class VmcSender:
    """Streams frames to a VMC marionette (an avatar host) over UDP, one bundle per frame."""

    def __init__(self, host: str, port: int) -> None:
        """Raises OSError for a host that does not resolve (once, here, not with every send)."""
        self._address = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4]
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, frame: VmcFrame, time: float) -> None:
        self.send_packet(frame_bundle(frame, time))

    def send_packet(self, packet: Packet | osc_bundle.OscBundle | osc_message.OscMessage) -> None:
        try:
            self._socket.sendto(packet.dgram, self._address)
        except ConnectionRefusedError:  # an ICMP "port unreachable" from an earlier datagram
            pass

    def close(self) -> None:
        self._socket.close()


_SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)  # Linux: datagrams the kernel dropped, per read


class VmcReceiver:
    """A VMC marionette: listens on UDP, assembles frames and hands each to ``on_frame``.

    One thread only reads datagrams into a queue, so that the socket buffer (``RECEIVE_BUFFER``
    asked for; the kernel caps it at ``net.core.rmem_max``) is drained however long a frame's work
    takes; a second thread parses them (python-osc), assembles frames and calls ``on_frame``.
    python-osc's Dispatcher is not used: it drops packets it cannot parse without a word and hides
    bundle boundaries, both of which this needs. On Linux the kernel's count of datagrams it dropped
    for want of buffer space is read with every datagram (``SO_RXQ_OVFL``) and reported as
    ``kernel_dropped`` in :attr:`counts`; ``backlog_max`` is the most datagrams that waited in the
    queue (the parsing thread behind the reader).

    Live means latest: a datagram that waited more than ``max_age`` seconds is dropped unparsed
    (``stale``), and a frame that is that old by the time it would be handed on gives way to a
    newer one made with it (``superseded``); so after any burst (a sender's backlog, a flood) the
    frames are current again as soon as the queue is drained of what is old, which takes
    microseconds per datagram. The queue never holds more than :data:`MAX_QUEUED_BYTES` (beyond,
    what arrives is dropped: ``overflow``).
    Each frame carries the arrival time of the datagram that completed it (``received_ns``).
    """

    def __init__(self, on_frame: Callable[[VmcFrame], None], host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT, buffer_bytes: int = RECEIVE_BUFFER,
                 max_age: float = MAX_AGE_S) -> None:
        self.on_frame = on_frame
        self.max_age_ns = round(max_age * 1e9)
        self.assembler = VmcFrameAssembler()
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, buffer_bytes)
            self._socket.setsockopt(socket.SOL_SOCKET, _SO_RXQ_OVFL, 1)
        except OSError:
            pass  # not Linux: no drop count
        try:
            self._socket.bind((host, port))
        except OSError:
            self._socket.close()
            raise
        self._socket.settimeout(0.1)  # the reader checks for close() this often
        self.buffer_bytes = self._socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self._queue: queue.SimpleQueue[tuple[int, bytes] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._datagrams = 0
        self._kernel_dropped = 0
        self._backlog = 0  # the most datagrams read but not yet parsed
        self._queued_bytes = 0
        self._stale = 0
        self._superseded = 0
        self._overflow = 0
        self._reader = threading.Thread(target=self._read, name="vmc-reader", daemon=True)
        self._worker = threading.Thread(target=self._work, name="vmc-frames", daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._socket.getsockname()[:2]

    @property
    def counts(self) -> dict[str, int]:
        with self._lock:
            counts = dict(self.assembler.counts)
        counts.update(datagrams=self._datagrams, kernel_dropped=self._kernel_dropped,
                      backlog_max=self._backlog, stale=self._stale, superseded=self._superseded,
                      overflow=self._overflow)
        return counts

    def start(self) -> VmcReceiver:
        self._worker.start()
        self._reader.start()
        return self

    def _read(self) -> None:
        space = socket.CMSG_SPACE(4)
        while not self._stop.is_set():
            try:
                data, ancillary, _, _ = self._socket.recvmsg(65535, space)
            except TimeoutError:
                continue
            except OSError:
                break
            for level, kind, value in ancillary:
                if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(value) >= 4:
                    self._kernel_dropped = struct.unpack("=I", value[:4])[0]
            self._datagrams += 1
            with self._lock:
                if self._queued_bytes + len(data) > MAX_QUEUED_BYTES:
                    self._overflow += 1
                    continue
                self._queued_bytes += len(data)
            self._queue.put((time.monotonic_ns(), data))
        self._queue.put(None)

    def _work(self) -> None:
        """Takes what is queued at once: what waited too long is dropped unparsed, the rest made
        into frames, and of those every one still fresh is handed on, and the newest in any case."""
        running = True
        while running:
            batch = [self._queue.get()]
            while batch[-1] is not None and not self._queue.empty():
                batch.append(self._queue.get())
            running = batch[-1] is not None
            batch = [item for item in batch if item is not None]
            self._backlog = max(self._backlog, len(batch) - 1)
            frames = []
            with self._lock:
                for arrived, data in batch:
                    self._queued_bytes -= len(data)
                    if time.monotonic_ns() - arrived > self.max_age_ns:
                        self._stale += 1
                        self.assembler.interrupt()
                        continue
                    frames += [(arrived, f) for f in self.assembler.feed_datagram(data)]
            for i, (arrived, f) in enumerate(frames):
                if i < len(frames) - 1 and time.monotonic_ns() - arrived > self.max_age_ns:
                    self._superseded += 1
                    continue
                self.on_frame(replace(f, received_ns=arrived))

    def close(self) -> None:
        self._stop.set()
        if self._reader.is_alive():
            self._reader.join()
        else:
            self._queue.put(None)
        if self._worker.is_alive():
            self._worker.join(timeout=5.0)
        self._socket.close()
