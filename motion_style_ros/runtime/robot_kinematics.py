"""The actuated tree of a robot (read from its URDF by :mod:`motion_style_ros.io.urdf`) as rigid
bodies, for :class:`~motion_style_ros.runtime.robot_target.RobotTarget`: forward kinematics of
every body at once (pointer doubling over the tree), which actuated joints move each body (the
analytic Jacobian's mask), joint axes and limits in URDF order. Pure numpy.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.urdf import RobotModel

ACTUATED = ("revolute", "continuous", "prismatic")


class Kinematics:
    """The actuated tree as rigid bodies: body 0 is the root link, body k + 1 the child link of
    actuated joint k (URDF order); fixed joints are folded into their parent's body."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        src = model.source
        children = defaultdict(list)
        for j in model.joints:
            children[j.parent].append(j)
        child_links = {j.child for j in model.joints}
        roots = [link for link in model.links if link not in child_links]
        if len(roots) != 1:
            raise MotionStyleError(f"{src}: expected one root link, found {len(roots)}: {roots[:4]}")
        root = roots[0]
        # A floating base declared against a 'world' link: the robot starts at that joint's child.
        while len(children[root]) == 1 and (children[root][0].kind in ("floating", "planar")
                                            or (root == "world" and children[root][0].kind == "fixed")):
            root = children[root][0].child
        self.root = root
        actuated = [j for j in model.joints if j.kind in ACTUATED and not j.mimic]
        index = {j.name: k for k, j in enumerate(actuated)}
        n = len(actuated)
        self.link_body: dict[str, int] = {root: 0}
        self.link_T: dict[str, np.ndarray] = {root: np.eye(4)}
        self.link_parent: dict[str, str] = {}
        self.body_parent = np.full(n, -1)
        self.origins = np.zeros((n, 4, 4))
        self.topo: list[int] = []
        stack = [root]
        while stack:
            link = stack.pop()
            for j in reversed(children[link]):
                if j.child in self.link_body:
                    raise MotionStyleError(f"{src}: link {j.child!r} is reached twice (not a tree)")
                self.link_parent[j.child] = link
                if j.name in index:
                    k = index[j.name]
                    self.body_parent[k] = self.link_body[link]
                    self.origins[k] = self.link_T[link] @ j.origin
                    self.link_body[j.child], self.link_T[j.child] = k + 1, np.eye(4)
                    self.topo.append(k)
                elif j.kind in ("fixed",) or j.mimic:
                    self.link_body[j.child] = self.link_body[link]
                    self.link_T[j.child] = self.link_T[link] @ j.origin
                else:
                    raise MotionStyleError(f"{src}: joint {j.name!r} is {j.kind}; only a floating "
                                           f"base and revolute, continuous, prismatic, fixed joints "
                                           f"are supported")
                stack.append(j.child)
        reached = [j for j in actuated if j.child in self.link_body]
        if len(reached) != n or n == 0:
            raise MotionStyleError(f"{src}: no actuated joints below the root link {root!r}")
        self.topo = sorted(self.topo, key=lambda k: self._depth(k))
        self.joints = actuated
        self.names = [j.name for j in actuated]
        self.n = n
        self.axes = np.array([j.axis / np.linalg.norm(j.axis) for j in actuated])
        self.prismatic = np.array([j.kind == "prismatic" for j in actuated])
        self.lower = np.array([j.lower for j in actuated])
        self.upper = np.array([j.upper for j in actuated])
        self.velocity = np.array([j.velocity for j in actuated])
        a = self.axes
        self._aa = a[:, :, None] * a[:, None, :]
        self._k = np.zeros((n, 3, 3))
        self._k[:, 0, 1], self._k[:, 0, 2], self._k[:, 1, 2] = -a[:, 2], a[:, 1], -a[:, 0]
        self._k[:, 1, 0], self._k[:, 2, 0], self._k[:, 2, 1] = a[:, 2], -a[:, 1], a[:, 0]
        # anc[b, k]: joint k moves body b.
        self.anc = np.zeros((n + 1, n))
        for b in range(1, n + 1):
            for k in self.path(b):
                self.anc[b, k] = 1.0
        self._eye3 = np.eye(3)
        self._any_prismatic = bool(self.prismatic.any())
        world = n + 1
        ancestor = np.array([world] + [int(b) for b in self.body_parent] + [world])
        self._doubling = []
        while (ancestor[:-1] != world).any():
            self._doubling.append(ancestor)
            ancestor = ancestor[ancestor]

    def _depth(self, k: int) -> int:
        d, b = 0, self.body_parent[k]
        while b > 0:
            d, b = d + 1, self.body_parent[b - 1]
        return d

    def path(self, body: int) -> list[int]:
        """Actuated joints from the root down to ``body`` (its own joint last)."""
        out = []
        while body > 0:
            out.append(body - 1)
            body = int(self.body_parent[body - 1])
        return out[::-1]

    def fk(self, q: np.ndarray) -> np.ndarray:
        """Body transforms ``(n + 1, 4, 4)`` in the root frame."""
        c, s = np.cos(q), np.sin(q)
        r = (c[:, None, None] * self._eye3 + (1.0 - c)[:, None, None] * self._aa
             + s[:, None, None] * self._k)
        t = np.empty((self.n + 2, 4, 4))  # bodies, then the world (identity) for pointer doubling
        t[0] = t[-1] = np.eye(4)
        t[1:-1] = self.origins
        if self._any_prismatic:
            p = self.prismatic
            r[p] = np.eye(3)
            t[1:-1][p, :3, 3] += np.einsum("kij,kj->ki", self.origins[p, :3, :3], self.axes[p]) * q[p, None]
        t[1:-1, :3, :3] = self.origins[:, :3, :3] @ r
        # Each body's transform relative to an ancestor twice as far up every round.
        for ancestors in self._doubling:
            t = t[ancestors] @ t
        return t[:-1]

    def link_frames(self, q: np.ndarray) -> dict[str, np.ndarray]:
        t = self.fk(q)
        return {link: t[b] @ self.link_T[link] for link, b in self.link_body.items()}


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis of broadcast arrays, without its axis bookkeeping."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out

