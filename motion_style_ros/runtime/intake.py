"""What a live frame must pass before a session sees it, so that no single frame can stop a stream
or poison its state (no ROS here: the stylizer node feeds it stamps, receipt times and values).

Each frame is checked against the last accepted one:

- **Values**: as many positions as names, all finite, angles within ``max_angle`` radians (beyond
  that a float32 angle is off by more than a milliradian: not a rotation anyone sent on purpose),
  the root within ``max_root_distance`` metres of the origin on every axis, and no faster than
  ``max_root_speed`` m/s from the previous frame (plus 5 cm of slack for jitter).
- **Stamps**: strictly after the previous one, and not running ahead of the clock the frames
  arrive by: a stamp that advances more than ``max_stamp_jump`` seconds beyond the receipt time that
  passed since the previous frame is dropped (``stamp_jump``; for a stream's first frame,
  ``future_stamp``: ahead of the receipt time itself). Stamps are compared step by step, so a bag
  replayed at any rate and a publisher that pauses pass; one corrupt stamp, a day ahead, does not.
- **Restarts**: frames that are dropped for their stamp or their place but agree with each other
  (a clock reset, a teleport, a looped clip, a mocap PC whose clock is ahead) restart the stream on
  their new timeline once they span ``restart_seconds`` (by their stamps or their arrival; at least
  three frames): no one has to call ``~/reset``.
- **Unstamped frames** (stamp 0) are stamped on the stream's own clock: the previous frame's stamp
  plus the receipt time since. A stamped frame right after one is never dropped for its stamp.
- **Gaps**: a step between accepted stamps of more than 1.5 nominal periods counts as a gap, and the
  frames it is missing are added up, so losses before the node (DDS, the network) show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_style_ros.errors import MotionStyleError

# Why a frame was dropped, as the diagnostics count them.
DROP_REASONS = ("mismatched_lengths", "non_finite", "bad_names", "duplicate_stamp", "out_of_order",
                "future_stamp", "stamp_jump", "implausible_angle", "implausible_root",
                "implausible_speed", "invalid_frame")
RESTART_REASONS = ("new_timeline", "non_finite_output")
SPEED_SLACK = 0.05  # m a root may move beyond max_root_speed * dt (stamp jitter)
RESTART_FRAMES = 3  # a new timeline needs at least this many frames
GAP_PERIODS = 1.5  # a step of more than this many nominal periods is a gap


class Dropped(Exception):
    """A frame that cannot be stylized: ``reason`` is one of :data:`DROP_REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


@dataclass(frozen=True)
class Bounds:
    """The limits of :class:`Intake` (the stylizer node's parameters of the same names)."""

    max_stamp_jump: float = 1.0  # s
    restart_seconds: float = 0.25  # s
    # m, per axis: a mocap volume, a game world, a robot walking for a day stay well inside; a
    # corrupt value (1e30) does not. The stream is translation-invariant this far out (1e-7).
    max_root_distance: float = 1e5
    max_root_speed: float = 20.0  # m/s (sprinters peak near 12)
    max_angle: float = 1e4  # rad

    def __post_init__(self) -> None:
        for name in ("max_stamp_jump", "restart_seconds", "max_root_distance", "max_root_speed", "max_angle"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise MotionStyleError(f"{name} must be a positive number, got {value!r}")


@dataclass
class Frame:
    """A frame as :meth:`Intake.admit` took it: ``stamp_ns`` is the stamp the session gets."""

    stamp_ns: int
    receipt_ns: int
    root: np.ndarray
    own_stamp: bool  # the stamp is the frame's own (not made up for an unstamped one, not shifted)
    restart: bool = False  # the frame starts a new timeline: restart the session's stream first


def _seconds(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


class Intake:
    """One performer's stream: :meth:`admit` each frame, :meth:`commit` it once the session took it
    (see the module docstring)."""

    def __init__(self, bounds: Bounds, period_s: float) -> None:
        self.bounds = bounds
        self.period_ns = round(period_s * 1e9)
        self.gaps = 0  # steps of more than GAP_PERIODS nominal periods
        self.frames_missing = 0  # frames those gaps lack at the nominal rate
        self.longest_gap_s = 0.0
        self.clear()

    def clear(self) -> None:
        """Forget the stream: the next frame may have any stamp and place."""
        self.last: Frame | None = None
        self._own_ns: int | None = None  # the last committed frame's own stamp
        self._candidate: tuple[Frame, int, Frame] | None = None  # a new timeline: first, count, last

    def check_values(self, names, positions) -> np.ndarray:
        """The positions as float64, or :class:`Dropped` (lengths, non-finite)."""
        values = np.asarray(positions, dtype=np.float64)
        if len(names) != len(values):
            raise Dropped("mismatched_lengths", f"{len(names)} names but {len(values)} positions")
        if not np.isfinite(values).all():
            bad = [names[i] for i in np.flatnonzero(~np.isfinite(values))[:5]]
            raise Dropped("non_finite", f"NaN or infinite positions for {bad}")
        return values

    def check_angles(self, angles: np.ndarray, names: list[str]) -> None:
        """:class:`Dropped` when an angle (radians, with the layout's names) is beyond ``max_angle``."""
        bad = np.abs(angles) > self.bounds.max_angle
        if bad.any():
            raise Dropped("implausible_angle", f"angles beyond +-{self.bounds.max_angle:g} rad for "
                          f"{[names[i] for i in np.flatnonzero(bad)[:5]]}")

    def admit(self, stamp_ns: int, receipt_ns: int, root: np.ndarray) -> Frame:
        """The frame to give the session (stamp 0: unstamped; ``root``: the pelvis in metres), or
        :class:`Dropped`. Nothing changes until :meth:`commit`, except that dropped frames may add
        up to a new timeline."""
        b = self.bounds
        root = np.asarray(root, dtype=np.float64)
        if np.abs(root).max() > b.max_root_distance:
            raise Dropped("implausible_root", f"root at {np.round(root, 2).tolist()} m, beyond "
                          f"+-{b.max_root_distance:g} m")
        last = self.last
        if stamp_ns == 0:  # on the stream's own clock
            taken = receipt_ns if last is None else last.stamp_ns + max(receipt_ns - last.receipt_ns, 1)
            frame = Frame(taken, receipt_ns, root, own_stamp=False)
        else:
            frame = Frame(stamp_ns, receipt_ns, root, own_stamp=True)
        if last is None:
            if frame.own_stamp and stamp_ns - receipt_ns > b.max_stamp_jump * 1e9:
                return self._refuse(frame, "future_stamp", f"stamp {_seconds(stamp_ns)} s is "
                                    f"{(stamp_ns - receipt_ns) * 1e-9:.3g} s ahead of its receipt")
            return frame
        if frame.own_stamp and frame.stamp_ns <= last.stamp_ns:
            if not last.own_stamp and (self._own_ns is None or stamp_ns > self._own_ns):
                # after an unstamped frame (or one shifted for it): a microsecond after it
                frame = Frame(last.stamp_ns + 1000, receipt_ns, root, own_stamp=False)
            elif stamp_ns == last.stamp_ns:
                raise Dropped("duplicate_stamp", f"stamp {_seconds(stamp_ns)} s again")
            else:
                return self._refuse(frame, "out_of_order", f"stamp {_seconds(stamp_ns)} s is not after "
                                    f"the previous frame's {_seconds(last.stamp_ns)} s")
        problem = self._step_problem(last, frame)
        if problem:
            return self._refuse(frame, *problem)
        return frame

    def commit(self, frame: Frame, own_stamp_ns: int) -> None:
        """The session took ``frame`` (``own_stamp_ns``: the message's stamp, 0 if none)."""
        last = self.last
        if last is not None and not frame.restart and self.period_ns > 0:
            step = frame.stamp_ns - last.stamp_ns
            if step > GAP_PERIODS * self.period_ns:
                self.gaps += 1
                self.frames_missing += round(step / self.period_ns) - 1
                self.longest_gap_s = max(self.longest_gap_s, step * 1e-9)
        self.last = frame
        if frame.restart:
            self._own_ns = None
        if own_stamp_ns:
            self._own_ns = own_stamp_ns
        self._candidate = None

    # --- internals --------------------------------------------------------------------------

    def _step_problem(self, last: Frame, frame: Frame) -> tuple[str, str] | None:
        b = self.bounds
        ahead = (frame.stamp_ns - last.stamp_ns) - (frame.receipt_ns - last.receipt_ns)
        if ahead > b.max_stamp_jump * 1e9:
            return "stamp_jump", (f"stamp {_seconds(frame.stamp_ns)} s ran {ahead * 1e-9:.3g} s ahead "
                                  f"of the time since the previous frame arrived")
        dt = (frame.stamp_ns - last.stamp_ns) * 1e-9
        moved = float(np.linalg.norm(frame.root - last.root))
        if moved > b.max_root_speed * dt + SPEED_SLACK:
            return "implausible_speed", (f"root moved {moved:.3g} m in {dt:.3g} s (at most "
                                         f"{b.max_root_speed:g} m/s)")
        return None

    def _refuse(self, frame: Frame, reason: str, detail: str) -> Frame:
        """Drop the frame, unless it and the dropped ones before it make a consistent timeline of
        ``restart_seconds``: then it starts the stream afresh on that timeline."""
        if self._candidate is not None:
            first, count, previous = self._candidate
            if frame.stamp_ns > previous.stamp_ns and self._step_problem(previous, frame) is None:
                span = max(frame.stamp_ns - first.stamp_ns, frame.receipt_ns - first.receipt_ns) * 1e-9
                if count + 1 >= RESTART_FRAMES and span >= self.bounds.restart_seconds:
                    frame.restart = True
                    return frame
                self._candidate = (first, count + 1, frame)
                raise Dropped(reason, detail)
        self._candidate = (frame, 1, frame)
        raise Dropped(reason, detail)
