"""Stick-figure pictures and animations of motions, side by side (matplotlib, drawn off-screen).

Each motion gets its own panel and scale (a body's span fills the panel whatever its units, so a CMU
clip in BVH units sits next to a canonical one in metres); the camera follows the pelvis, so a long
walk stays in view. Left limbs are blue, right ones red. Motion Y-up is drawn Z-up.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError

# Figures are made with matplotlib.figure.Figure, not pyplot: they render with Agg whatever backend
# the caller's matplotlib uses, and nothing global changes or needs closing.

_COLOURS = {"left": "#1f5fbf", "right": "#c8322d", "centre": "#303030"}
_PANEL_INCHES = (2.4, 2.8)


def _side(name: str) -> str:
    """Body side from a joint name (``Hand_L``, ``LeftArm``, ``LHipJoint``, ``RightToes``)."""
    if name.endswith("_L") or name.startswith("Left") or (name[:1] == "L" and name[1:2].isupper()):
        return "left"
    if name.endswith("_R") or name.startswith("Right") or (name[:1] == "R" and name[1:2].isupper()):
        return "right"
    return "centre"


class _Body:
    """A motion's joint positions in the drawing frame, and how to draw and frame them."""

    def __init__(self, motion: Motion) -> None:
        sk: Skeleton = motion.skeleton
        pos = motion.global_positions()
        self.pos = np.stack([pos[..., 2], pos[..., 0], pos[..., 1]], axis=-1)  # forward, left, up
        self.pelvis = sk.pelvis or next((j for j, n in enumerate(sk.names) if n == "Hips"), 0)
        # The body is the pelvis and what hangs below it (not a static root such as joint_Root).
        body = {self.pelvis}
        for j, p in enumerate(sk.parents):
            if p in body:
                body.add(j)
        self.bones = [(sk.parents[j], j) for j in sorted(body - {self.pelvis})]
        self.colours = [_COLOURS[_side(sk.names[j])] for _, j in self.bones]
        joints = sorted(body)
        self.span = float(np.ptp(self.pos[:, joints], axis=1).max()) or 1.0
        self.floor = min(float(self.pos[:, joints, 2].min()), 0.0)


class _Panel:
    """One body drawn in one 3D axes, re-centred on the pelvis for each frame shown."""

    def __init__(self, ax, body: _Body, title: str) -> None:
        self.ax, self.body = ax, body
        self.lines = Line3DCollection([], colors=body.colours, linewidths=2.2)
        ax.add_collection3d(self.lines, autolim=False)
        self._ground()
        ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.5)
        ax.set_proj_type("ortho")
        ax.view_init(elev=12, azim=35)
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)

    def _ground(self) -> None:
        """Floor grid under the whole path and the pelvis track on it."""
        b = self.body
        step = b.span / 4
        track = b.pos[:, b.pelvis]
        lo = np.floor((track[:, :2].min(axis=0) - b.span) / step) * step
        hi = np.ceil((track[:, :2].max(axis=0) + b.span) / step) * step
        xs, ys = (np.arange(lo[k], hi[k] + step / 2, step) for k in (0, 1))
        segs = [((x, lo[1], b.floor), (x, hi[1], b.floor)) for x in xs]
        segs += [((lo[0], y, b.floor), (hi[0], y, b.floor)) for y in ys]
        grid = Line3DCollection(segs, colors="#d8d8d8", linewidths=0.6)
        self.ax.add_collection3d(grid, autolim=False)
        self.ax.plot(track[:, 0], track[:, 1], np.full(len(track), b.floor), color="#9a9a9a", lw=0.8)

    def show(self, frame: int) -> None:
        b = self.body
        p = b.pos[frame]
        self.lines.set_segments([(p[i], p[j]) for i, j in b.bones])
        cx, cy = p[b.pelvis, :2]
        half = 0.55 * b.span
        self.ax.set_xlim(cx - half, cx + half)
        self.ax.set_ylim(cy - half, cy + half)
        self.ax.set_zlim(b.floor - 0.02 * b.span, b.floor + 1.08 * b.span)


def _check(motions: Sequence[Motion], titles: Sequence[str]) -> None:
    if not motions:
        raise MotionStyleError("nothing to render: no motions given")
    if len(titles) != len(motions):
        raise MotionStyleError(f"{len(motions)} motions but {len(titles)} titles")


def render_png(motions: Sequence[Motion], titles: Sequence[str], path: str | Path,
               frames: int = 6, dpi: int = 100) -> None:
    """A strip of ``frames`` evenly spaced poses per motion: one row per motion, time left to right."""
    _check(motions, titles)
    cols = max(int(frames), 1)
    fig = Figure(figsize=(_PANEL_INCHES[0] * cols, _PANEL_INCHES[1] * len(motions)))
    for row, (motion, title) in enumerate(zip(motions, titles)):
        body = _Body(motion)
        picks = np.linspace(0, motion.n_frames - 1, cols).round().astype(int)
        for col, f in enumerate(picks):
            ax = fig.add_subplot(len(motions), cols, row * cols + col + 1, projection="3d")
            label = f"{title}  {f / motion.fps:.2f} s" if col == 0 else f"{f / motion.fps:.2f} s"
            _Panel(ax, body, label).show(f)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0, hspace=0.05)
    fig.savefig(path, dpi=dpi)


def render_gif(motions: Sequence[Motion], titles: Sequence[str], path: str | Path,
               fps: float = 15.0, seconds: float | None = None, dpi: int = 90) -> None:
    """An animation with the motions side by side, resampled to ``fps`` (nearest frame).

    It lasts as long as the longest motion (or ``seconds``); shorter ones hold their last pose.
    """
    _check(motions, titles)
    duration = max(m.duration for m in motions) if seconds is None else seconds
    if not (fps > 0 and duration > 0):
        raise MotionStyleError(f"a GIF needs a positive rate and length, got {fps:g} fps, {duration:g} s")
    times = np.arange(0.0, duration, 1.0 / fps)
    fig = Figure(figsize=(_PANEL_INCHES[0] * len(motions), _PANEL_INCHES[1]))
    panels = [_Panel(fig.add_subplot(1, len(motions), i + 1, projection="3d"), _Body(m), t)
              for i, (m, t) in enumerate(zip(motions, titles))]
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    index = [np.minimum((times * m.fps).round().astype(int), m.n_frames - 1) for m in motions]

    def draw(k: int) -> list:
        for panel, idx in zip(panels, index):
            panel.show(int(idx[k]))
        return [panel.lines for panel in panels]

    FuncAnimation(fig, draw, frames=len(times), blit=False).save(
        str(path), writer=PillowWriter(fps=fps), dpi=dpi
    )
