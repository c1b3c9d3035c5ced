"""Reference clips for a live node, read off the thread that streams (no ROS here).

Setting the ``reference`` parameter must not stall the streams: a clip is checked at once
(:meth:`References.check`: a regular file within the BVH size limit, never opened if it is not;
a BVH whose header, frame count and numbers hold; long enough), so that ``ros2 param set`` fails
with the reason; then it is read, retargeted and encoded on a worker thread
(:meth:`References.load`). When it is ready, the change it belongs to is queued for the streams'
thread, which applies it before its next frame; a clip that turns out unusable queues a revert to
the clip in use instead, with its one-line reason (kept in :attr:`References.failure` for the
diagnostics). A clip asked for after another makes the earlier one's result stale: only the newest
one is applied.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.canonical import canonical_clip

REVERT = "_revert_reference"  # the key of a queued revert: the clip (or '') to go back to


class References:
    """The reference clips of one node's sessions (``session``: any of them; they share the model);
    ``empty``: what no clip ('') means for them, as the log says it."""

    def __init__(self, session, pending: deque[dict], log_error: Callable[[str], None],
                 empty: str = "the latent seed") -> None:
        self.session = session
        self.pending = pending  # the node's queue of changes for the streams' thread, in order
        self.log_error = log_error
        self.empty = empty
        self.staged: dict[str, tuple] = {}  # clip path -> its codes and logits, once read
        self._loads = 0  # loads started; a newer one makes an older one's result stale
        self.failure: str | None = None  # why the last clip asked for could not be used, until one is

    def check(self, path: str) -> None:
        """What can be known of a clip at once, or a one-line reason it cannot serve."""
        frames, frame_time = bvh.header(path)
        s = self.session
        if frames * frame_time * s.fps < s.window:
            raise MotionStyleError(
                f"reference clip too short: {frames * frame_time:.2f} s; it needs at least "
                f"{s.window / s.fps:.1f} s ({s.window} frames at {s.fps:g} fps)")

    def read(self, path: str) -> tuple:
        """A clip's style codes and logits (the slow part: read, retarget, encode)."""
        return self.session.reference_codes(canonical_clip(path))

    def load(self, path: str, previous: str, changes: dict) -> threading.Thread:
        """Read ``path`` on a worker thread, then queue ``changes``; if the clip is unusable, log
        why and queue a revert to ``previous``."""
        self._loads += 1
        worker = threading.Thread(target=self._load, args=(path, previous, changes, self._loads), daemon=True)
        worker.start()
        return worker

    def _load(self, path: str, previous: str, changes: dict, load: int) -> None:
        try:
            self.staged[path] = self.read(path)
        except MotionStyleError as exc:
            self.failure = f"{' '.join(str(exc).split())}; kept {previous or self.empty!r}"
            self.log_error(f"parameter reference: {' '.join(str(exc).split())}; keeping "
                           f"{previous or self.empty!r}")
            self.pending.append({REVERT: previous})
            return
        self.failure = None
        if load == self._loads:  # else a newer clip was asked for meanwhile
            self.pending.append(changes)
