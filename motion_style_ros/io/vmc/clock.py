"""Stamps for a VMC sender's frames that keep the sender's rhythm."""

from __future__ import annotations


class SenderClock:
    """Stamps for a sender's frames: its own ``/VMC/Ext/T`` when that advances, else arrival time.

    A sender's clock spaces its frames as it made them, so stamps taken from it keep the stream's
    rhythm however the network, the sender or a scheduler hold up and bunch the datagrams. The stamp
    is the sender's time plus an offset that follows the least delayed arrivals (the lower envelope
    of arrival minus sender time), and the offset only ever slews, so stamps keep their spacing to
    within a fraction: it drops to a less delayed arrival by at most half a frame step at a time,
    creeps up by ``drift`` (1000 ppm) of the time that passed so a slow sender clock is followed,
    and once frames have trailed their arrival by more than ``tolerance`` seconds for ``patience``
    seconds of sender time (a sender that fell behind and stays behind; a sender held up for a
    moment that then sends its backlog keeps its stamps) it catches up at ``catch_up`` (10 %: frame
    steps 1.1 times longer) until they trail by less. A time that does not advance (an epoch time sent as float32 moves in 128 s
    steps) stamps the frame with its arrival time, and one that would stamp a frame more than
    ``jump`` (1 s) after its arrival (a time that jumped ahead) anchors the clock at that arrival
    again; less than that (a sender that was behind catching up) is slewed down like any less
    delayed arrival. Stamps always increase, by at least half the sender's frame step.
    """

    def __init__(self, tolerance: float = 0.1, drift: float = 1e-3, catch_up: float = 0.1,
                 patience: float = 0.5, jump: float = 1.0) -> None:
        self.tolerance_ns = round(tolerance * 1e9)
        self.jump_ns = round(jump * 1e9)
        self.drift = drift
        self.catch_up = catch_up
        self.patience = patience
        self._late_since: float | None = None
        self._offset: int | None = None
        self._time: float | None = None
        self._now = 0
        self._last = 0

    def stamp(self, sender_time: float | None, now_ns: int) -> int:
        """The stamp (ns) of a frame with ``sender_time`` (seconds, or None) that completed at
        ``now_ns``."""
        stamp = now_ns
        if sender_time is None or self._time is None or sender_time <= self._time:
            self._offset = None  # no time, or one that does not advance: arrival time
        if sender_time is not None:
            t_ns = round(sender_time * 1e9)
            arrival = now_ns - t_ns  # the offset that would stamp this frame on arrival
            if self._offset is None or self._offset - arrival > self.jump_ns:
                self._offset = arrival
            else:
                step = (sender_time - self._time) * 1e9
                if arrival < self._offset:  # less delayed than any before: slew down to it
                    self._offset = max(arrival, self._offset - round(0.5 * step))
                else:
                    late = arrival - self._offset > self.tolerance_ns
                    self._late_since = (self._late_since if self._late_since is not None
                                        else sender_time) if late else None
                    behind = late and sender_time - self._late_since > self.patience
                    up = self.catch_up * step if behind else self.drift * max(step, now_ns - self._now)
                    self._offset = min(arrival, self._offset + round(up))
            stamp = t_ns + self._offset
            self._time = sender_time
        self._now = now_ns
        self._last = max(stamp, self._last + 1)
        return self._last
