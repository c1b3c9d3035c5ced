"""Stylized frames as JointTrajectory chunks for ros2_control's JointTrajectoryController (no ROS
here: the stylizer node turns each :class:`Chunk` into a message).

- **Points**: one per frame, ``time_from_start`` keeping the frames' spacing, the first one a
  nominal frame period after the start (the chunk starts on receipt: header stamp 0).
- **Angles** are unwrapped against the previous point, so nothing jumps by 2 pi inside a chunk or
  between chunks.
- **Velocities** are central differences of the positions (forward or backward at a stream's ends),
  so the controller interpolates with cubic splines instead of linearly. By default (``inner``)
  the chunk's last point carries none: JointTrajectoryController rejects a trajectory that ends
  with a non-zero velocity unless ``allow_nonzero_velocity_at_trajectory_end`` is set, and the next
  chunk replaces it before its last point is reached. ``all`` gives the last point its backward
  difference (for controllers configured with that flag); ``none`` sends positions only (e.g. for
  the controller's own ``positions_upsampling``).
- **Gaps**: a chunk is sent early when the stream has a gap (or the caller flushes it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

VELOCITIES = ("inner", "all", "none")
TWO_PI = 2.0 * np.pi


@dataclass
class Chunk:
    times_ns: list[int]  # time_from_start of each point
    positions: np.ndarray  # (N, J)
    velocities: list[np.ndarray | None]  # per point: (J,) or None (no velocities)


class Chunker:
    """One stream's chunks of ``points`` frames; ``angular``: per name, an angle to unwrap."""

    def __init__(self, points: int, period_ns: int, gap_seconds: float, velocities: str = "inner") -> None:
        if velocities not in VELOCITIES:
            raise ValueError(f"velocities must be one of {', '.join(VELOCITIES)}, got {velocities!r}")
        self.points, self.period_ns, self.velocities = points, period_ns, velocities
        self.gap_ns = round(gap_seconds * 1e9)
        self.angular = np.zeros(0, dtype=bool)
        self.clear()

    def clear(self, angular: np.ndarray | None = None) -> None:
        """Forget the stream (new names: their ``angular`` mask); a queued chunk is dropped, so
        :meth:`flush` first."""
        if angular is not None:
            self.angular = np.asarray(angular, dtype=bool)
        self._stamps: list[int] = []
        self._points: list[np.ndarray] = []
        self._before: tuple[int, np.ndarray] | None = None  # the point before the queued ones

    def add(self, stamp_ns: int, positions: np.ndarray) -> list[Chunk]:
        """Queue a frame; the chunks that are complete now (none, one, or two at a gap)."""
        out = []
        if self._stamps and stamp_ns - self._stamps[-1] > self.gap_ns:
            out += self.flush()
            self._before = None  # nothing to unwrap or differentiate against across a gap
        point = np.array(positions, dtype=np.float64)
        previous = self._points[-1] if self._points else None if self._before is None else self._before[1]
        if previous is not None and len(previous) == len(point):
            a = self.angular
            point[a] = previous[a] + np.mod(point[a] - previous[a] + np.pi, TWO_PI) - np.pi
        self._stamps.append(stamp_ns)
        self._points.append(point)
        if len(self._points) == self.points:
            out += self.flush()
        return out

    def flush(self) -> list[Chunk]:
        """The queued points as a chunk (none queued: no chunk)."""
        if not self._points:
            return []
        stamps = ([self._before[0]] if self._before else []) + self._stamps
        points = ([self._before[1]] if self._before else []) + self._points
        t = (np.array(stamps) - stamps[0]) * 1e-9  # relative: 1e9 s stamps would lose microseconds
        p = np.array(points)
        if len(p) > 1:
            grad = np.gradient(p, t, axis=0, edge_order=1)
        else:
            grad = np.zeros_like(p)
        if self._before:
            grad = grad[1:]
        n = len(self._points)
        vel: list[np.ndarray | None] = [None] * n
        if self.velocities != "none":
            vel = list(grad)
            if self.velocities == "inner":
                vel[-1] = None
        first = self._stamps[0]
        chunk = Chunk([s - first + self.period_ns for s in self._stamps], np.array(self._points), vel)
        self._before = (self._stamps[-1], self._points[-1])
        self._stamps, self._points = [], []
        return [chunk]
