"""What the core's compiled arithmetic shares: numba's one signature for every kernel (:func:`rows`),
quaternion and vector helpers, and forward kinematics. The kernels themselves live beside the
concept they compute (the features' encoding in :mod:`.feature_kernels`, the foot lock in
:mod:`.foot_lock`, the arm rolls in :mod:`.roll_kernels`, the layout's Euler angles in
:mod:`motion_style_ros.io.joint_state`, standing, proportions, slerp and Hermite in their modules).

Why compiled: a streamed frame is a few dozen numbers per performer, and in numpy each operation
on them costs its call overhead (about a microsecond) more than its arithmetic; a model frame took
hundreds of such calls. Compiled, a row costs its arithmetic. The same kernels serve whole clips
(rows are frames) and streams (rows are performers), so there is one implementation of each; the
classes that own the state (``StreamEncoder``, ``FootLock``, ...) keep it in arrays that the
kernels update in place.

Callers pass float64 C-contiguous writeable arrays (:func:`rows`), int64 index arrays and Python
scalars, so that each kernel has one signature. Kernels compile on first use and are cached on disk
(numba's ``cache=True``: beside their module, or in ~/.cache/numba where the package's folder is
read-only): :func:`motion_style_ros.runtime.warmup.warm_kernels` pays that before a node
subscribes. Quaternions are ``(w, x, y, z)`` as in :mod:`~motion_style_ros.core.rotations`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

EPS = 1e-12  # rotations._EPS: the smallest norm a vector is divided by


def rows(x, dtype=np.float64) -> np.ndarray:
    """``x`` as a C-contiguous writeable array of ``dtype``, the kernels' one signature: ``x``
    itself when it already is one. ``np.require`` does the same at several microseconds a call,
    and a streamed model frame makes a dozen of them."""
    if (type(x) is np.ndarray and x.dtype == dtype and x.flags.c_contiguous
            and x.flags.writeable):
        return x
    return np.require(x, dtype, "CW")


@njit(cache=True)
def qmul(a, b, out) -> None:
    """``out = a * b`` (Hamilton product; ``out`` may not alias ``a`` or ``b``)."""
    aw, ax, ay, az = a[0], a[1], a[2], a[3]
    bw, bx, by, bz = b[0], b[1], b[2], b[3]
    out[0] = aw * bw - ax * bx - ay * by - az * bz
    out[1] = aw * bx + ax * bw + ay * bz - az * by
    out[2] = aw * by - ax * bz + ay * bw + az * bx
    out[3] = aw * bz + ax * by - ay * bx + az * bw


@njit(cache=True)
def norm3(x: float, y: float, z: float) -> float:
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def quat_entries(q):
    """The rotation matrix of ``q`` normalised (``rotations.to_matrix``), row by row, as nine
    numbers (no array to allocate in an inner loop)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    n = max(n, EPS)
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)


@njit(cache=True)
def quat_matrix(q, m) -> None:
    """:func:`quat_entries` into ``m`` (3, 3)."""
    m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2] = quat_entries(q)


@njit(cache=True)
def fk_row(parents, rotations, positions, g_rot, g_pos) -> None:
    """One pose's global rotations ``(J, 4)`` and positions ``(J, 3)`` into ``g_rot``, ``g_pos``."""
    m = np.empty((3, 3))
    for j in range(rotations.shape[0]):
        p = parents[j]
        if p < 0:
            g_rot[j] = rotations[j]
            g_pos[j] = positions[j]
            continue
        qmul(g_rot[p], rotations[j], g_rot[j])
        quat_matrix(g_rot[p], m)
        t = positions[j]
        for a in range(3):
            g_pos[j, a] = g_pos[p, a] + m[a, 0] * t[0] + m[a, 1] * t[1] + m[a, 2] * t[2]


@njit(cache=True)
def forward_kinematics(parents, rotations, positions):
    """Global rotations ``(N, J, 4)`` and positions ``(N, J, 3)`` of ``N`` poses from local
    rotations ``(N, J, 4)`` and translations ``(N, J, 3)`` (parents before children)."""
    n, joints = rotations.shape[0], rotations.shape[1]
    g_rot = np.empty((n, joints, 4))
    g_pos = np.empty((n, joints, 3))
    for r in range(n):
        fk_row(parents, rotations[r], positions[r], g_rot[r], g_pos[r])
    return g_rot, g_pos


@njit(cache=True)
def rest_pose(offsets, pelvis, root, positions) -> None:
    """``motion.rest_positions`` of one pose into ``positions`` ``(J, 3)``."""
    positions[:] = offsets
    positions[pelvis] = root


@njit(cache=True)
def facing_angle(g_pos, across) -> float:
    """The heading (rad about +Y, 0 facing +Z) of one pose ``(J, 3)`` from the left-right axis of
    hips and shoulders (``across``: left and right upper leg, left and right upper arm)."""
    ul, ur, al, ar = across[0], across[1], across[2], across[3]
    ax = (g_pos[ul, 0] - g_pos[ur, 0]) + (g_pos[al, 0] - g_pos[ar, 0])
    az = (g_pos[ul, 2] - g_pos[ur, 2]) + (g_pos[al, 2] - g_pos[ar, 2])
    return math.atan2(-az, ax)  # forward = across x up


@njit(cache=True)
def wrap_angle(angle: float) -> float:
    """An angle (rad) into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def rotate_vector(q, v, out) -> None:
    """``rotations.rotate`` of one vector: ``out = R(q normalised) v`` (``out`` may alias ``v``)."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = quat_entries(q)
    v0, v1, v2 = v[0], v[1], v[2]
    out[0] = m00 * v0 + m01 * v1 + m02 * v2
    out[1] = m10 * v0 + m11 * v1 + m12 * v2
    out[2] = m20 * v0 + m21 * v1 + m22 * v2


@njit(cache=True)
def quat_between(u, v, q) -> None:
    """``rotations.between``: the shortest arc taking direction ``u`` onto ``v``, into ``q``."""
    nu = max(norm3(u[0], u[1], u[2]), EPS)
    nv = max(norm3(v[0], v[1], v[2]), EPS)
    u0, u1, u2 = u[0] / nu, u[1] / nu, u[2] / nu
    v0, v1, v2 = v[0] / nv, v[1] / nv, v[2] / nv
    w = 1.0 + u0 * v0 + u1 * v1 + u2 * v2
    x, y, z = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    if w < 1e-9:  # 180 degrees: about an axis orthogonal to u (u x the least-used unit axis)
        a0, a1, a2 = abs(u0), abs(u1), abs(u2)
        if a0 <= a1 and a0 <= a2:
            x, y, z = 0.0, u2, -u1
        elif a1 <= a2:
            x, y, z = -u2, 0.0, u0
        else:
            x, y, z = u1, -u0, 0.0
    n = max(math.sqrt(w * w + x * x + y * y + z * z), EPS)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit(cache=True)
def unit_clip(x: float) -> float:
    return min(max(x, -1.0), 1.0)


@njit(cache=True)
def local_rotation(parent, world, out) -> None:
    """``out = conjugate(parent) * world``: a world rotation in its parent's frame."""
    inverse = np.empty(4)
    inverse[0], inverse[1], inverse[2], inverse[3] = parent[0], -parent[1], -parent[2], -parent[3]
    qmul(inverse, world, out)
