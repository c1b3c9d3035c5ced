"""Overlap-add of model windows into a stream with a fixed latency, for several streams at once.

A windowed model sees the last ``window`` frames and returns a frame for each. A frame is emitted
``lookahead`` frames after it arrived, so only the last ``lookahead + 1`` outputs of a window are
ever used: a window that ends at the newest frame ``n`` contributes to frames ``n - lookahead ..
n``. Each emitted frame is the weighted mean of the contributions it received. The weight of a
window's contribution is a smooth bump over those ``lookahead + 1`` positions, near zero at both
ends, so a window fades in and out of the output instead of switching on and off at a seam.
Identical windows therefore give back their frames exactly (a weighted mean of equal values).
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.errors import MotionStyleError

Mask = np.ndarray | slice | int | None


def taper(length: int) -> np.ndarray:
    """``length`` positive weights, a raised-cosine bump sampled at the cells' centres."""
    return np.sin(np.pi * (np.arange(length) + 0.5) / length) ** 2


class OverlapAdd:
    """Accumulates windows of ``channels`` values per frame for ``streams`` streams.

    Slot ``j`` (0..lookahead) holds frame ``n - lookahead + j``, ``n`` the newest frame; slot 0 is
    the frame due now. :meth:`shift` moves on by one frame.
    """

    def __init__(self, window: int, lookahead: int, streams: int, channels: int) -> None:
        if not 0 <= lookahead < window:
            raise MotionStyleError(
                f"lookahead must be 0 to {window - 1} frames (less than the window), got {lookahead}"
            )
        self.window, self.lookahead = window, lookahead
        self.weights = taper(lookahead + 1)
        self._sum = np.zeros((streams, lookahead + 1))
        self._acc = np.zeros((streams, lookahead + 1, channels))

    def add(self, outputs: np.ndarray, which: Mask = None) -> None:
        """A window ending at the newest frame: ``(streams, window, channels)`` outputs (or only
        the streams ``which`` selects)."""
        which = slice(None) if which is None else which
        used = np.asarray(outputs, dtype=np.float64)[:, self.window - self.lookahead - 1 :]
        self._acc[which] += self.weights[:, None] * used
        self._sum[which] += self.weights

    def covered(self, slot: int = 0) -> np.ndarray:
        """``(streams,)`` bool: the frame in ``slot`` has at least one contribution."""
        return self._sum[:, slot] > 0

    def frame(self, slot: int | np.ndarray = 0) -> np.ndarray:
        """``(streams, channels)``: the blended frame in ``slot`` (one slot for all streams or one
        per stream); streams without contributions there give NaN."""
        rows = np.arange(len(self._sum))
        slot = np.broadcast_to(slot, rows.shape)
        with np.errstate(invalid="ignore", divide="ignore"):
            return self._acc[rows, slot] / self._sum[rows, slot][:, None]

    def shift(self) -> None:
        """One frame on: the due frame leaves, an empty newest slot comes in."""
        for kept in (self._acc, self._sum):  # in place: np.roll allocates and costs several times more
            kept[:, :-1] = kept[:, 1:]
            kept[:, -1] = 0.0

    def clear(self, which: Mask = None) -> None:
        """Forget every contribution of these streams (a restart)."""
        which = slice(None) if which is None else which
        self._acc[which] = 0.0
        self._sum[which] = 0.0
