"""The core's per-pose arithmetic compiled with numba, one pose (a row) at a time: forward
kinematics, heading, features and their inverse, and each step of a streamed frame's conditioning
and clean-up (foot lock, standing, ground following, arm rolls, size, slerp, Hermite output).

Why compiled: a streamed frame is a few dozen numbers per performer, and in numpy each operation
on them costs its call overhead (about a microsecond) more than its arithmetic; a model frame took
hundreds of such calls. Compiled, a row costs its arithmetic. The same kernels serve whole clips
(rows are frames) and streams (rows are performers), so there is one implementation of each; the
classes that own the state (``StreamEncoder``, ``FootLock``, ...) keep it in arrays that the
kernels update in place.

Callers pass float64 C-contiguous writeable arrays (:func:`rows`), int64
index arrays and Python scalars, so that each kernel has one signature. Kernels compile on first
use and are cached on disk (numba's ``cache=True``: beside this file, or in ~/.cache/numba where
the package's folder is read-only): :func:`motion_style_ros.runtime.warmup.warm_kernels` pays that
before a node subscribes. Quaternions are ``(w, x, y, z)`` as in
:mod:`~motion_style_ros.core.rotations`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_EPS = 1e-12  # rotations._EPS: the smallest norm a vector is divided by


def rows(x, dtype=np.float64) -> np.ndarray:
    """``x`` as a C-contiguous writeable array of ``dtype``, the kernels' one signature: ``x``
    itself when it already is one. ``np.require`` does the same at several microseconds a call,
    and a streamed model frame makes a dozen of them."""
    if (type(x) is np.ndarray and x.dtype == dtype and x.flags.c_contiguous
            and x.flags.writeable):
        return x
    return np.require(x, dtype, "CW")


@njit(cache=True)
def _qmul(a, b, out) -> None:
    """``out = a * b`` (Hamilton product; ``out`` may not alias ``a`` or ``b``)."""
    aw, ax, ay, az = a[0], a[1], a[2], a[3]
    bw, bx, by, bz = b[0], b[1], b[2], b[3]
    out[0] = aw * bw - ax * bx - ay * by - az * bz
    out[1] = aw * bx + ax * bw + ay * bz - az * by
    out[2] = aw * by - ax * bz + ay * bw + az * bx
    out[3] = aw * bz + ax * by - ay * bx + az * bw


@njit(cache=True)
def _norm3(x: float, y: float, z: float) -> float:
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def _entries(q):
    """The rotation matrix of ``q`` normalised (``rotations.to_matrix``), row by row, as nine
    numbers (no array to allocate in an inner loop)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    n = max(n, _EPS)
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)


@njit(cache=True)
def _matrix(q, m) -> None:
    """:func:`_entries` into ``m`` (3, 3)."""
    m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2] = _entries(q)


@njit(cache=True)
def _fk_row(parents, rotations, positions, g_rot, g_pos) -> None:
    """One pose's global rotations ``(J, 4)`` and positions ``(J, 3)`` into ``g_rot``, ``g_pos``."""
    m = np.empty((3, 3))
    for j in range(rotations.shape[0]):
        p = parents[j]
        if p < 0:
            g_rot[j] = rotations[j]
            g_pos[j] = positions[j]
            continue
        _qmul(g_rot[p], rotations[j], g_rot[j])
        _matrix(g_rot[p], m)
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
        _fk_row(parents, rotations[r], positions[r], g_rot[r], g_pos[r])
    return g_rot, g_pos


@njit(cache=True)
def _rest(offsets, pelvis, root, positions) -> None:
    """``motion.rest_positions`` of one pose into ``positions`` ``(J, 3)``."""
    positions[:] = offsets
    positions[pelvis] = root


@njit(cache=True)
def _yaw(g_pos, across) -> float:
    """The heading (rad about +Y, 0 facing +Z) of one pose ``(J, 3)`` from the left-right axis of
    hips and shoulders (``across``: left and right upper leg, left and right upper arm)."""
    ul, ur, al, ar = across[0], across[1], across[2], across[3]
    ax = (g_pos[ul, 0] - g_pos[ur, 0]) + (g_pos[al, 0] - g_pos[ar, 0])
    az = (g_pos[ul, 2] - g_pos[ur, 2]) + (g_pos[al, 2] - g_pos[ar, 2])
    return math.atan2(-az, ax)  # forward = across x up


@njit(cache=True)
def facing_yaw(g_pos, across):
    """:func:`_yaw` of poses ``(N, J, 3)``."""
    yaw = np.empty(g_pos.shape[0])
    for r in range(g_pos.shape[0]):
        yaw[r] = _yaw(g_pos[r], across)
    return yaw


@njit(cache=True)
def _wrap(angle: float) -> float:
    """An angle (rad) into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def encode_rows(joints, feet, heights, pelvis, rotations, pelvis_rot, g_pos, prev_g_pos, yaw, prev_yaw,
                fps, contact_speed, size):
    """``(N, size)`` float32 features (``features``' layout: root 4, rot6d, pos, vel, contact) of
    poses given each one's previous pose (global positions and heading). ``pelvis_rot``: the
    pelvis's global rotation ``(N, 4)``; ``joints``: the layout's joints; ``feet`` and
    ``heights``: the contact joints and their heights."""
    out = np.empty((rotations.shape[0], size), dtype=np.float32)
    for r in range(rotations.shape[0]):
        _features(joints, feet, heights, pelvis, rotations[r], pelvis_rot[r], g_pos[r], prev_g_pos[r], yaw[r],
                  prev_yaw[r], fps, contact_speed, out[r])
    return out


@njit(cache=True)
def encode_stream(parents, offsets, pelvis, across, joints, feet, heights, rotations, roots, last, last_yaw,
                  fresh, fps, contact_speed, size):
    """One streamed frame of ``P`` performers: forward kinematics, heading and
    :func:`encode_rows`' features ``(P, size)``, each performer's previous pose from ``last``
    ``(P, J, 3)`` and ``last_yaw`` (its own on a ``fresh`` one: zero velocities), which are then
    updated to this frame in place (``fresh`` cleared)."""
    n, n_joints = rotations.shape[0], rotations.shape[1]
    out = np.empty((n, size), dtype=np.float32)
    positions = np.empty((n_joints, 3))
    g_rot = np.empty((n_joints, 4))
    g_pos = np.empty((n_joints, 3))
    for r in range(n):
        _rest(offsets, pelvis, roots[r], positions)
        _fk_row(parents, rotations[r], positions, g_rot, g_pos)
        yaw = _yaw(g_pos, across)
        if fresh[r]:
            last[r] = g_pos
            last_yaw[r] = yaw
        _features(joints, feet, heights, pelvis, rotations[r], g_rot[pelvis], g_pos, last[r], yaw, last_yaw[r],
                  fps, contact_speed, out[r])
        last[r] = g_pos
        last_yaw[r] = yaw
        fresh[r] = False
    return out


@njit(cache=True)
def _features(joints, feet, heights, pelvis, rotations, pelvis_rot, g_pos, prev_g_pos, yaw, prev_yaw, fps,
              contact_speed, out) -> None:
    """One pose's features into ``out`` (see :func:`encode_rows`)."""
    k = joints.shape[0]
    m = np.empty((3, 3))
    q = np.empty(4)
    inv = np.empty(4)
    rot6d, pos, vel, contact = 4, 4 + 6 * k, 4 + 9 * k, 4 + 12 * k
    half = 0.5 * yaw
    inv[0], inv[1], inv[2], inv[3] = math.cos(half), 0.0, -math.sin(half), 0.0
    _matrix(inv, m)  # into the facing frame
    gx, gz = g_pos[pelvis, 0], g_pos[pelvis, 2]
    px, pz = prev_g_pos[pelvis, 0], prev_g_pos[pelvis, 2]
    vx, vz = (gx - px) * fps, (gz - pz) * fps
    out[0] = m[0, 0] * vx + m[0, 2] * vz
    out[1] = m[2, 0] * vx + m[2, 2] * vz
    out[2] = g_pos[pelvis, 1]
    out[3] = _wrap(yaw - prev_yaw) * fps
    for i in range(k):
        j = joints[i]
        if i == 0:  # the pelvis relative to the facing frame
            _qmul(inv, pelvis_rot, q)
        else:
            q[:] = rotations[j]
        _six(q, out, rot6d + 6 * i)
        r0, r1, r2 = g_pos[j, 0] - gx, g_pos[j, 1], g_pos[j, 2] - gz
        d0 = (g_pos[j, 0] - prev_g_pos[j, 0]) * fps
        d1 = (g_pos[j, 1] - prev_g_pos[j, 1]) * fps
        d2 = (g_pos[j, 2] - prev_g_pos[j, 2]) * fps
        for a in range(3):
            out[pos + 3 * i + a] = m[a, 0] * r0 + m[a, 1] * r1 + m[a, 2] * r2
            out[vel + 3 * i + a] = m[a, 0] * d0 + m[a, 1] * d1 + m[a, 2] * d2
    for i in range(feet.shape[0]):
        f = feet[i]
        speed = _norm3(g_pos[f, 0] - prev_g_pos[f, 0], g_pos[f, 1] - prev_g_pos[f, 1],
                       g_pos[f, 2] - prev_g_pos[f, 2]) * fps
        out[contact + i] = 1.0 if (g_pos[f, 1] < heights[i] and speed < contact_speed) else 0.0


@njit(cache=True)
def _six(q, out, at) -> None:
    """``rotations.to_6d``: the first two columns of ``q``'s matrix into ``out[at:at + 6]``."""
    m00, m01, _, m10, m11, _, m20, m21, _ = _entries(q)
    out[at], out[at + 1], out[at + 2] = m00, m10, m20
    out[at + 3], out[at + 4], out[at + 5] = m01, m11, m21


@njit(cache=True)
def _from_6d(d, at, q) -> None:
    """``rotations.from_6d`` of ``d[at:at + 6]`` into ``q``: Gram-Schmidt to a matrix, then the
    best-conditioned column of ``4 q q^T`` (Shepperd), ``w >= 0``, normalised."""
    a0, a1, a2 = d[at], d[at + 1], d[at + 2]
    b0, b1, b2 = d[at + 3], d[at + 4], d[at + 5]
    na = max(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), _EPS)
    x0, x1, x2 = a0 / na, a1 / na, a2 / na
    dot = x0 * b0 + x1 * b1 + x2 * b2
    b0, b1, b2 = b0 - dot * x0, b1 - dot * x1, b2 - dot * x2
    nb = max(math.sqrt(b0 * b0 + b1 * b1 + b2 * b2), _EPS)
    y0, y1, y2 = b0 / nb, b1 / nb, b2 / nb
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    # the matrix's columns are x, y, z: m[row, col]
    m00, m01, m02 = x0, y0, z0
    m10, m11, m12 = x1, y1, z1
    m20, m21, m22 = x2, y2, z2
    d0 = 1.0 + m00 + m11 + m22
    d1 = 1.0 + m00 - m11 - m22
    d2 = 1.0 - m00 + m11 - m22
    d3 = 1.0 - m00 - m11 + m22
    best, top = 0, d0
    if d1 > top:
        best, top = 1, d1
    if d2 > top:
        best, top = 2, d2
    if d3 > top:
        best = 3
    if best == 0:
        w, x, y, z = d0, m21 - m12, m02 - m20, m10 - m01
    elif best == 1:
        w, x, y, z = m21 - m12, d1, m01 + m10, m02 + m20
    elif best == 2:
        w, x, y, z = m02 - m20, m01 + m10, d2, m12 + m21
    else:
        w, x, y, z = m10 - m01, m02 + m20, m12 + m21, d3
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = max(math.sqrt(w * w + x * x + y * y + z * z), _EPS)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit(cache=True)
def pose_rows(joints, pelvis, n_joints, features, yaw, ground):
    """Local rotations ``(N, J, 4)`` and pelvis positions ``(N, 3)`` of decoded rows (``features``
    ``(N, >= 4 + 6 * len(joints))``: root and rot6d blocks) placed at ``ground`` ``(N, 3)`` with
    heading ``yaw`` ``(N,)``; joints outside ``joints`` stay the identity."""
    n = features.shape[0]
    rotations = np.empty((n, n_joints, 4))
    root = np.empty((n, 3))
    for r in range(n):
        _pose(joints, pelvis, features[r], yaw[r], ground[r], rotations[r], root[r])
    return rotations, root


@njit(cache=True)
def decode_stream(joints, pelvis, n_joints, features, yaw, ground, fresh, fps):
    """One streamed frame of ``P`` performers: each one's heading ``yaw`` ``(P,)`` and ground point
    ``ground`` ``(P, 3)`` integrated in place by its root block's yaw rate, then its velocity in
    the new facing frame (a ``fresh`` one stays where it was placed; ``fresh`` cleared), and
    :func:`pose_rows` there."""
    n = features.shape[0]
    rotations = np.empty((n, n_joints, 4))
    root = np.empty((n, 3))
    for r in range(n):
        if not fresh[r]:
            yaw[r] = _step_root(features[r], yaw[r], ground[r], ground[r], fps)
        fresh[r] = False
        _pose(joints, pelvis, features[r], yaw[r], ground[r], rotations[r], root[r])
    return rotations, root


@njit(cache=True)
def trajectory(features, start_ground, start_yaw, fps):
    """Heading ``(T,)`` and ground point ``(T, 3)`` of decoded frames ``(T, >= 4)`` integrated from
    frame 0's ``start_ground`` (horizontal) and ``start_yaw``, as :func:`decode_stream` does."""
    n = features.shape[0]
    yaw = np.empty(n)
    ground = np.zeros((n, 3))
    if n == 0:
        return yaw, ground
    yaw[0], ground[0, 0], ground[0, 2] = start_yaw, start_ground[0], start_ground[2]
    for t in range(1, n):
        yaw[t] = _step_root(features[t], yaw[t - 1], ground[t - 1], ground[t], fps)
    return yaw, ground


@njit(cache=True)
def _step_root(f, yaw, ground, out, fps) -> float:
    """One frame of a decoded trajectory: the heading turned by the root block's yaw rate, then
    the ground point moved by its velocity in the new facing frame (``out`` may be ``ground``);
    returns the heading."""
    yaw += f[3] / fps
    cos, sin = math.cos(yaw), math.sin(yaw)
    out[0] = ground[0] + (cos * f[0] + sin * f[1]) / fps
    out[2] = ground[2] + (cos * f[1] - sin * f[0]) / fps
    return yaw


@njit(cache=True)
def _pose(joints, pelvis, f, yaw, ground, rotations, root) -> None:
    """One decoded row's local rotations ``(J, 4)`` and pelvis position ``(3,)``."""
    local = np.empty(4)
    turn = np.empty(4)
    rotations[:] = 0.0
    rotations[:, 0] = 1.0
    for i in range(joints.shape[0]):
        _from_6d(f, 4 + 6 * i, local)
        if i == 0:
            half = 0.5 * yaw
            turn[0], turn[1], turn[2], turn[3] = math.cos(half), 0.0, math.sin(half), 0.0
            _qmul(turn, local, rotations[pelvis])
        else:
            rotations[joints[i]] = local
    root[0] = ground[0]
    root[1] = ground[1] + f[2]
    root[2] = ground[2]


@njit(cache=True)
def _rotate(q, v, out) -> None:
    """``rotations.rotate`` of one vector: ``out = R(q normalised) v`` (``out`` may alias ``v``)."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = _entries(q)
    v0, v1, v2 = v[0], v[1], v[2]
    out[0] = m00 * v0 + m01 * v1 + m02 * v2
    out[1] = m10 * v0 + m11 * v1 + m12 * v2
    out[2] = m20 * v0 + m21 * v1 + m22 * v2


@njit(cache=True)
def _between(u, v, q) -> None:
    """``rotations.between``: the shortest arc taking direction ``u`` onto ``v``, into ``q``."""
    nu = max(_norm3(u[0], u[1], u[2]), _EPS)
    nv = max(_norm3(v[0], v[1], v[2]), _EPS)
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
    n = max(math.sqrt(w * w + x * x + y * y + z * z), _EPS)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit(cache=True)
def _unit_clip(x: float) -> float:
    return min(max(x, -1.0), 1.0)


@njit(cache=True)
def lock_feet(parents, offsets, pelvis, hips, knees, ankles, toes, heights, rotations, roots, inputs,
              last, last_out, last_root, back, target, landed, offset, heading, turn, glide, weight, locked,
              axis, placed, fps, speed, max_stretch, fade, clearance, anchor_root, anchor_stretch, glide_rate, near,
              down_height, anchor_ease, swing_reach, eps):
    """:class:`~motion_style_ros.core.foot_lock.FootLock`'s frame (see its module for what each
    step does and why): the output's local rotations ``(P, J, 4)`` and roots ``(P, 3)``, the lock's
    state arrays updated in place; ``inputs`` ``(P, 2, 3)``: the input's ankles."""
    n, n_joints = rotations.shape[0], rotations.shape[1]
    out = rotations.copy()
    root = roots.copy()
    positions = np.empty((n_joints, 3))
    g_rot = np.empty((n, n_joints, 4))
    g_pos = np.empty((n, n_joints, 3))
    foot_turn = np.empty((n, 2))
    goal = np.empty((n, 2, 3))
    moved = np.zeros((n, 2), dtype=np.bool_)
    was = locked.copy()
    toe = np.empty(3)
    any_moved = False
    for r in range(n):
        _rest(offsets, pelvis, roots[r], positions)
        _fk_row(parents, rotations[r], positions, g_rot[r], g_pos[r])
        contact = np.zeros(2, dtype=np.bool_)
        forward = np.zeros(2)  # how far the ankle is in front of its hip (along its foot), 0 to 1
        held = np.empty(2)
        away = np.empty((2, 3))
        for s in range(2):
            a = ankles[s]
            d0, d1, d2 = inputs[r, s, 0] - last[r, s, 0], inputs[r, s, 1] - last[r, s, 1], inputs[r, s, 2] - last[r, s, 2]
            moving = _norm3(d0, d1, d2) * fps  # NaN on a first frame
            last[r, s] = inputs[r, s]
            contact[s] = inputs[r, s, 1] < heights[s] and moving < speed
            start = contact[s] and not was[r, s]
            if was[r, s] and contact[s]:  # a new lock glides on with the stylizer's ankle, less each frame
                for c in range(3):
                    target[r, s, c] += glide[r, s] * (g_pos[r, a, c] - last_out[r, s, c])
            glide[r, s] = glide_rate if start else glide[r, s] * glide_rate
            last_out[r, s] = g_pos[r, a]
            if start:  # where the stylizer's ankle lands, under where the output's last was
                target[r, s] = g_pos[r, a]
                if not math.isnan(placed[r, s, 0]):
                    target[r, s, 0], target[r, s, 2] = placed[r, s, 0], placed[r, s, 2]
                landed[r, s] = inputs[r, s]
            _rotate(g_rot[r, a], toes[s], toe)
            ahead_of_hip = ((g_pos[r, a, 0] - g_pos[r, hips[s], 0]) * toe[0]
                            + (g_pos[r, a, 2] - g_pos[r, hips[s], 2]) * toe[2]) / max(math.hypot(toe[0], toe[2]), eps)
            forward[s] = min(max(ahead_of_hip / swing_reach, 0.0), 1.0)
            h = math.atan2(toe[0], toe[2])
            if start:
                heading[r, s] = h
            held[s] = _wrap(heading[r, s] - h)
            for c in range(3):
                away[s, c] = g_pos[r, a, c] - target[r, s, c]
        if anchor_root:
            step = np.empty(3)
            for c in range(3):
                step[c] = root[r, c] - last_root[r, c]
                if math.isnan(step[c]):  # a first frame: no step to hold back
                    step[c] = 0.0
            step[1] = 0.0
            length = _norm3(step[0], step[1], step[2])
            for c in range(3):
                step[c] /= max(length, eps)
            want = 0.0
            for s in range(2):
                ahead = np.empty(3)
                for c in range(3):
                    ahead[c] = away[s, c] - (inputs[r, s, c] - landed[r, s, c])
                reach = _norm3(ahead[0], ahead[1], ahead[2])
                down = was[r, s] and reach > anchor_stretch and g_pos[r, ankles[s], 1] < heights[s] + down_height
                if down:
                    scale = 1.0 - anchor_stretch / max(reach, eps)
                    want = max(want, scale * (ahead[0] * step[0] + ahead[1] * step[1] + ahead[2] * step[2]))
            back[r] = min(back[r] + anchor_ease * (want - back[r]), length)
            for c in range(3):
                shift = -step[c] * back[r]
                root[r, c] += shift
                for s in range(2):
                    g_pos[r, hips[s], c] += shift
                    g_pos[r, knees[s], c] += shift
                    g_pos[r, ankles[s], c] += shift
                    away[s, c] += shift
        last_root[r] = root[r]
        for s in range(2):
            a = ankles[s]
            reach = _norm3(away[s, 0], away[s, 1], away[s, 2])
            if was[r, s] and reach > max_stretch:  # the leash
                for c in range(3):
                    target[r, s, c] += away[s, c] * (1.0 - max_stretch / max(reach, eps))
            if was[r, s] and not contact[s]:  # released: the correction then fades out
                for c in range(3):
                    offset[r, s, c] = target[r, s, c] - g_pos[r, a, c]
                turn[r, s] = held[s]
            locked[r, s] = contact[s]
            weight[r, s] = 1.0 if contact[s] else max(weight[r, s] - fade, 0.0)
            x = min(max(weight[r, s], 0.0), 1.0)
            eased = x * x * (3.0 - 2.0 * x)  # easing.smoothstep
            for c in range(3):
                goal[r, s, c] = target[r, s, c] if contact[s] else g_pos[r, a, c] + eased * offset[r, s, c]
            foot_turn[r, s] = held[s] if contact[s] else eased * turn[r, s]
            if clearance and not contact[s] and inputs[r, s, 1] > goal[r, s, 1]:
                # lifted as high as the input's: a leg reaching forward swings up about the hip at
                # the stylizer's extension (bending a straight leg's knee turns it far for a few
                # cm); one behind the hip bends its knee (its toes would drag); in between, the
                # goal goes part of the way, by how far forward the ankle is
                hip = hips[s]
                dx, dz = goal[r, s, 0] - g_pos[r, hip, 0], goal[r, s, 2] - g_pos[r, hip, 2]
                extent2 = ((g_pos[r, a, 0] - g_pos[r, hip, 0]) ** 2 + (g_pos[r, a, 1] - g_pos[r, hip, 1]) ** 2
                           + (g_pos[r, a, 2] - g_pos[r, hip, 2]) ** 2)
                goal[r, s, 1] = inputs[r, s, 1]
                drop = goal[r, s, 1] - g_pos[r, hip, 1]
                across = math.sqrt(dx * dx + dz * dz)
                if forward[s] > 0.0 and extent2 > drop * drop and across > eps:
                    scale = 1.0 + forward[s] * (math.sqrt(extent2 - drop * drop) / across - 1.0)
                    goal[r, s, 0] = g_pos[r, hip, 0] + scale * dx
                    goal[r, s, 2] = g_pos[r, hip, 2] + scale * dz
            gap = _norm3(goal[r, s, 0] - g_pos[r, a, 0], goal[r, s, 1] - g_pos[r, a, 1], goal[r, s, 2] - g_pos[r, a, 2])
            moved[r, s] = gap > near or abs(foot_turn[r, s]) > near
            placed[r, s] = goal[r, s]
            any_moved = any_moved or moved[r, s]
    if not any_moved:
        return out, root
    u, v, bent, swing, q, tmp, upper, lower, foot = (np.empty(3), np.empty(3), np.empty(3), np.empty(4),
                                                      np.empty(4), np.empty(4), np.empty(4), np.empty(4),
                                                      np.empty(4))
    for r in range(n):
        for s in range(2):
            hip, knee, ankle = hips[s], knees[s], ankles[s]
            # two-bone IK: bend the knee to the goal's distance, then swing the hip onto the goal
            for c in range(3):
                u[c] = g_pos[r, hip, c] - g_pos[r, knee, c]
                v[c] = g_pos[r, ankle, c] - g_pos[r, knee, c]
            a, b = _norm3(u[0], u[1], u[2]), _norm3(v[0], v[1], v[2])
            k0, k1, k2 = u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]
            size = _norm3(k0, k1, k2)
            if size > 1e-6 * a * b:  # the last good knee axis is kept for a straight leg
                d = max(size, eps)
                axis[r, s, 0], axis[r, s, 1], axis[r, s, 2] = k0 / d, k1 / d, k2 / d
            known = axis[r, s, 0] != 0.0 or axis[r, s, 1] != 0.0 or axis[r, s, 2] != 0.0
            to_goal = _norm3(goal[r, s, 0] - g_pos[r, hip, 0], goal[r, s, 1] - g_pos[r, hip, 1],
                             goal[r, s, 2] - g_pos[r, hip, 2])
            c_len = min(max(to_goal, abs(a - b) + 1e-4), a + b - 1e-4)
            now = math.acos(_unit_clip((u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / max(a * b, eps)))
            wanted = math.acos(_unit_clip((a * a + b * b - c_len * c_len) / max(2 * a * b, eps)))
            half = 0.5 * (wanted - now if known else 0.0)
            sin = math.sin(half)
            q[0], q[1], q[2], q[3] = math.cos(half), sin * axis[r, s, 0], sin * axis[r, s, 1], sin * axis[r, s, 2]
            _rotate(q, v, bent)
            for c in range(3):
                bent[c] += g_pos[r, knee, c] - g_pos[r, hip, c]  # the bent ankle, from the hip
                u[c] = goal[r, s, c] - g_pos[r, hip, c]
            _between(bent, u, swing)
            _qmul(swing, g_rot[r, hip], upper)
            _qmul(q, g_rot[r, knee], tmp)
            _qmul(swing, tmp, lower)
            half = 0.5 * foot_turn[r, s]
            tmp[0], tmp[1], tmp[2], tmp[3] = math.cos(half), 0.0, math.sin(half), 0.0
            _qmul(tmp, g_rot[r, ankle], foot)
            if not moved[r, s]:
                continue
            # local = the parent's world rotation's inverse times the world rotation
            _local(g_rot[r, parents[hip]], upper, out[r, hip])
            _local(upper, lower, out[r, knee])
            _local(lower, foot, out[r, ankle])
    return out, root


@njit(cache=True)
def _local(parent, world, out) -> None:
    """``out = conjugate(parent) * world``: a world rotation in its parent's frame."""
    inverse = np.empty(4)
    inverse[0], inverse[1], inverse[2], inverse[3] = parent[0], -parent[1], -parent[2], -parent[3]
    _qmul(inverse, world, out)


@njit(cache=True)
def add_arm_moments(rotations, positions, joints, upper, lower, hang_cos, live, second, first, count) -> None:
    """:func:`~motion_style_ros.core.conform.arm_moments` of one streamed frame added in place to
    the moments of the ``live`` performers: ``second`` ``(P, K, 9, 9)``, ``first`` ``(P, K, 9)``
    and ``count`` ``(P, K)`` of the arm joints ``joints`` (the left arm's then the right's, ``K``
    in all), counting an arm's joints on a frame where it hangs (its upper arm ``upper[side]`` to
    ``lower[side]`` within the angle whose cosine is ``hang_cos`` of straight down, from the
    global ``positions``)."""
    per_arm = joints.shape[0] // 2
    m = np.empty((3, 3))
    for r in range(rotations.shape[0]):
        if not live[r]:
            continue
        for side in range(2):
            b0 = positions[r, lower[side], 0] - positions[r, upper[side], 0]
            b1 = positions[r, lower[side], 1] - positions[r, upper[side], 1]
            b2 = positions[r, lower[side], 2] - positions[r, upper[side], 2]
            if not -b1 > hang_cos * max(_norm3(b0, b1, b2), 1e-9):
                continue
            for i in range(side * per_arm, (side + 1) * per_arm):
                _matrix(rotations[r, joints[i]], m)
                v = m.ravel()
                for a in range(9):
                    first[r, i, a] += v[a]
                    for b in range(9):
                        second[r, i, a, b] += v[a] * v[b]
                count[r, i] += 1.0


@njit(cache=True)
def stand(contact, sides, columns, frame, hold, ease, still, weight, output, features):
    """:class:`~motion_style_ros.core.standing.Standing`'s frame: the model's output rows ``(P, >=
    4)`` as float64 with the root motion (``columns``) of performers standing on both feet
    eased into that of ``features`` ``(P, F)``; ``still`` and ``weight`` ``(P,)`` updated in place.
    ``contact``: the features' first contact column; ``sides`` ``(feet, 2)``: each foot's side."""
    out = output.copy()
    for r in range(out.shape[0]):
        left = right = 0.0
        for i in range(sides.shape[0]):
            if features[r, contact + i] > 0.5:
                left += sides[i, 0]
                right += sides[i, 1]
        still[r] = still[r] + frame if min(left, right) > 0.0 else 0.0
        step = ease if still[r] >= hold - 1e-9 else -ease
        weight[r] = min(max(weight[r] + step, 0.0), 1.0)
        x = min(max(weight[r], 0.0), 1.0)
        w = x * x * (3.0 - 2.0 * x)  # easing.smoothstep
        if w == 0.0:
            continue
        for c in columns:
            out[r, c] = (1.0 - w) * out[r, c] + w * features[r, c]
    return out


@njit(cache=True)
def follow_ground(ankles, last, offset, fps, speed, height, down, up) -> None:
    """:class:`~motion_style_ros.core.conform.StreamGround`'s frame: each performer's ``offset``
    ``(P,)`` moved towards the height of its lower still ankle (slower than ``speed``; ``ankles``
    ``(P, 2, 3)``, ``last`` the previous frame's, NaN after a start) above ``height``, at rate
    ``down`` when lower and ``up[r]`` when higher; ``last`` becomes ``ankles``."""
    for r in range(ankles.shape[0]):
        lowest = np.inf
        for s in range(2):
            moved = _norm3(ankles[r, s, 0] - last[r, s, 0], ankles[r, s, 1] - last[r, s, 1],
                           ankles[r, s, 2] - last[r, s, 2])
            if moved * fps < speed:  # NaN on a first frame: not still
                lowest = min(lowest, ankles[r, s, 1])
            last[r, s] = ankles[r, s]
        if lowest == np.inf:
            continue
        error = (lowest - height) - offset[r]
        offset[r] += (down if error < 0.0 else up[r]) * error


@njit(cache=True)
def _stance(root_velocity, leg_velocity, scale, min_speed, residual_fraction):
    """One frame's least-squares sums ``(-v . l, l . l)`` of its stance foot (the contact point
    whose world velocity at this ``scale`` is least; see ``proportions._stance_sums``), or zeros
    where no foot is planted: horizontal root velocity ``(2,)``, contact points' ``(K, 2)``."""
    best, foot = np.inf, 0
    for k in range(leg_velocity.shape[0]):
        w0 = root_velocity[0] + scale * leg_velocity[k, 0]
        w1 = root_velocity[1] + scale * leg_velocity[k, 1]
        moving = w0 * w0 + w1 * w1
        if moving < best:
            best, foot = moving, k
    l0, l1 = leg_velocity[foot, 0], leg_velocity[foot, 1]
    square = l0 * l0 + l1 * l1
    speed = math.sqrt(square)
    if speed > min_speed and math.sqrt(best) < residual_fraction * scale * speed:
        return -(root_velocity[0] * l0 + root_velocity[1] * l1), square
    return 0.0, 0.0


@njit(cache=True)
def stance_rows(root_velocity, leg_velocity, scale, min_speed, residual_fraction):
    """:func:`_stance` of frames: ``(N, 2)``, ``(N, K, 2)``, ``(N,)`` -> the sums ``(N,)`` twice."""
    n = root_velocity.shape[0]
    cross, square = np.empty(n), np.empty(n)
    for r in range(n):
        cross[r], square[r] = _stance(root_velocity[r], leg_velocity[r], scale[r], min_speed, residual_fraction)
    return cross, square


@njit(cache=True)
def observe_scale(relative_points, relative, step, frozen, measured_before, cross, square, target, scale, fps,
                  reference, prior, low, high, min_speed, residual_fraction, evidence, off, gain):
    """:meth:`~motion_style_ros.core.proportions.StreamScale.observe`'s frame, the state arrays
    updated in place: ``relative_points`` ``(P, K, 3)`` the contact points relative to the pelvis,
    ``relative`` ``(P, K, 2)`` the last frame's (horizontal; NaN after a start), ``step`` ``(P, 3)``
    the root's last displacement; the sums ``cross``, ``square``, the estimate ``target`` and the
    applied ``scale`` ``(P,)``. Returns the performers whose size has just been measured."""
    n, k = relative_points.shape[0], relative_points.shape[1]
    have = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        have[r] = not (math.isnan(relative[r, 0, 0]) or math.isnan(step[r, 0]) or frozen[r])
    root_v = np.empty(2)
    leg_v = np.empty((k, 2))
    measured = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        if have[r]:
            for a, c in ((0, 0), (1, 2)):
                root_v[a] = (0.0 if math.isnan(step[r, c]) else step[r, c]) * fps
                for i in range(k):
                    d = relative_points[r, i, c] - relative[r, i, a]
                    leg_v[i, a] = (0.0 if math.isnan(d) else d) * fps
            c_add, s_add = _stance(root_v, leg_v, target[r] * reference, min_speed, residual_fraction)
            cross[r] += c_add
            square[r] += s_add
        if have.any() and not frozen[r]:  # proportions._estimate
            ratio = (cross[r] + prior * reference) / (square[r] + prior) / reference
            target[r] = min(max(ratio, low), high)
        for i in range(k):
            relative[r, i, 0] = relative_points[r, i, 0]
            relative[r, i, 1] = relative_points[r, i, 2]
        if frozen[r]:
            continue
        enough = square[r] >= evidence
        measured[r] = not measured_before[r] and enough and abs(target[r] - scale[r]) >= off
        measured_before[r] = measured_before[r] or enough
        scale[r] += (1.0 if measured[r] else gain) * (target[r] - scale[r])
    return measured


@njit(cache=True)
def rolls_due(live, frames, count, per_arm, restarted, settle, every, late, sure):
    """Which performers' arm rolls :class:`~motion_style_ros.core.conform.StreamRolls` solves on
    this frame (``frames`` ``(P,)`` counted in place for the ``live`` ones): every ``every``
    frames for the first ``settle``, and every frame while an arm has hung in at most ``sure``
    frames, until first measured (``restarted``); every ``late`` frames after."""
    due = np.zeros(live.shape[0], dtype=np.bool_)
    for r in range(live.shape[0]):
        if not live[r]:
            continue
        frames[r] += 1
        n = frames[r]
        early = n <= settle
        fewest = np.inf
        for i in range(0, count.shape[1], per_arm):
            fewest = min(fewest, count[r, i])
        first = early and not restarted[r] and fewest <= sure
        due[r] = (n % (every if early else late)) == 0 or first
    return due


@njit(cache=True)
def ease_rolls(live, due, frames, settle, restarted, target, angles, gain, restart):
    """The applied rolls ``angles`` ``(P, K)`` moved the short way towards ``target`` by ``gain``,
    in place, for the ``live`` performers; at once for one whose rolls were first measured on this
    frame ``restart`` (rad) or more off. Returns those (``restarted`` updated)."""
    measured = np.zeros(live.shape[0], dtype=np.bool_)
    turn = np.empty(angles.shape[1])
    for r in range(live.shape[0]):
        largest = 0.0
        for i in range(angles.shape[1]):
            d = target[r, i] - angles[r, i]
            turn[i] = math.atan2(math.sin(d), math.cos(d))
            largest = max(largest, abs(turn[i]))
        measured[r] = due[r] and not restarted[r] and frames[r] <= settle and largest >= restart
        restarted[r] = restarted[r] or measured[r]
        if live[r]:
            g = 1.0 if measured[r] else gain
            for i in range(angles.shape[1]):
                angles[r, i] += g * turn[i]
    return measured


@njit(cache=True)
def solve_rolls(coefficients, basis, constant, grid, second, first, count, per_chain, sure, low, high,
                min_frames, unrolled):
    """:meth:`~motion_style_ros.core.conform.RollModel.solve`: the rolls ``(P, K)`` of each arm
    chain (``per_chain`` joints, chains one after the other) from the moments ``second``
    ``(P, K, 9, 9)``, ``first`` ``(P, K, 9)`` and counts ``(P, K)``. Each joint's cost at the
    ``grid`` (A,) roll pairs is ``basis @ C @ basis.T + count * constant`` with ``C`` (5, 5)
    the ``coefficients`` (K, 25, 90) times the moments; a dynamic programme chooses a chain's grid
    rolls (the chain's first parent keeps its frame), a parabola through each joint's cost refines
    it within half a grid step, and the chain is scaled by how clearly it beats no rolls
    (``low``, ``high``; below ``sure`` frames all or nothing, below ``min_frames`` none). The
    ``unrolled`` joints (K,) are solved with their chain and then left at 0."""
    p_count, k_count = count.shape
    steps = grid.shape[0]
    step = grid[1]
    out = np.zeros((p_count, k_count))
    moments = np.empty(90)
    c = np.empty(25)
    half = np.empty((steps, 5))
    across = np.ascontiguousarray(basis.T)
    costs = np.empty((per_chain, steps, steps))
    total = np.empty(steps)
    nxt = np.empty(steps)
    back = np.zeros((per_chain, steps), dtype=np.int64)
    choice = np.zeros(per_chain, dtype=np.int64)
    near = np.empty(3)
    for r in range(p_count):
        for chain in range(k_count // per_chain):
            for k in range(per_chain):
                j = chain * per_chain + k
                for u in range(9):
                    for v in range(9):
                        moments[9 * u + v] = second[r, j, u, v]
                    moments[81 + u] = first[r, j, u]
                for i in range(25):
                    acc = 0.0
                    for m in range(90):
                        acc += coefficients[j, i, m] * moments[m]
                    c[i] = acc
                for a in range(steps):
                    for v in range(5):
                        acc = 0.0
                        for u in range(5):
                            acc += basis[a, u] * c[5 * u + v]
                        half[a, v] = acc
                shift = count[r, j] * constant[j]
                for a in range(steps):
                    row = costs[k, a]
                    row[:] = shift
                    for v in range(5):
                        h = half[a, v]
                        for b in range(steps):
                            row[b] += h * across[v, b]
            for b in range(steps):
                total[b] = costs[0, 0, b]
            for k in range(1, per_chain):
                nxt[:] = np.inf
                for a in range(steps):  # a running minimum over parents, the first on ties
                    t = total[a]
                    for b in range(steps):
                        value = t + costs[k, a, b]
                        if value < nxt[b]:
                            nxt[b] = value
                            back[k, b] = a
                total[:] = nxt
            last = 0
            for b in range(1, steps):
                if total[b] < total[last]:
                    last = b
            choice[per_chain - 1] = last
            for k in range(per_chain - 1, 0, -1):
                choice[k - 1] = back[k, choice[k]]
            unrolled_cost = 0.0
            for k in range(per_chain):
                unrolled_cost += costs[k, 0, 0]
            frames = count[r, chain * per_chain]
            gain = (unrolled_cost - total[last]) / max(frames, 1.0)
            lo = low if frames >= sure else high - 1e-6
            weight = min(max((gain - lo) / (high - lo), 0.0), 1.0) if frames >= min_frames else 0.0
            for k in range(per_chain):
                parent = choice[k - 1] if k > 0 else 0
                for d in range(3):
                    b = (choice[k] + d - 1) % steps
                    near[d] = costs[k, parent, b]
                    if k < per_chain - 1:
                        near[d] += costs[k + 1, b, choice[k + 1]]
                curve = near[0] - 2.0 * near[1] + near[2]
                offset = 0.5 * (near[0] - near[2]) / curve if curve > 1e-12 else 0.0
                offset = min(max(offset, -0.5), 0.5)
                j = chain * per_chain + k
                if not unrolled[j]:
                    x = grid[choice[k]] + offset * step
                    out[r, j] = weight * math.atan2(math.sin(x), math.cos(x))
    return out


@njit(cache=True)
def roll_rows(rotations, joints, angles, per_arm, undo):
    """:func:`~motion_style_ros.core.conform.apply_rolls` of poses ``(N, J, 4)``: each arm joint's
    local rotation (``joints``, ``per_arm`` to a chain) turned by its own roll's inverse on the
    right and its chain parent's roll on the left (``angles`` ``(N, K)``; negated unless
    ``undo``), a copy."""
    out = rotations.copy()
    roll = np.empty(4)
    before = np.empty(4)
    q = np.empty(4)
    sign = 1.0 if undo else -1.0
    for r in range(out.shape[0]):
        for i in range(joints.shape[0]):
            j = joints[i]
            half = 0.5 * sign * angles[r, i]
            roll[0], roll[1], roll[2], roll[3] = math.cos(half), -math.sin(half), 0.0, 0.0  # conjugated
            _qmul(out[r, j], roll, q)
            if i % per_arm:
                half = 0.5 * sign * angles[r, i - 1]
                before[0], before[1], before[2], before[3] = math.cos(half), math.sin(half), 0.0, 0.0
                _qmul(before, q, out[r, j])
            else:
                out[r, j] = q
    return out


@njit(cache=True)
def pull_stream(ground, yaw, to_ground, to_yaw, fresh, gain) -> None:
    """Each performer's integrated ``ground`` point ``(P, 3)`` (horizontal) and heading ``yaw``
    moved the fraction ``gain`` of the way towards ``to_ground`` and ``to_yaw`` (the short way
    round), in place, except for a ``fresh`` one (placed, not integrated yet)."""
    for r in range(ground.shape[0]):
        if fresh[r]:
            continue
        ground[r, 0] += gain * (to_ground[r, 0] - ground[r, 0])
        ground[r, 1] += gain * (0.0 - ground[r, 1])
        ground[r, 2] += gain * (to_ground[r, 2] - ground[r, 2])
        yaw[r] += gain * _wrap(to_yaw[r] - yaw[r])


@njit(cache=True)
def check_frame(rotations, roots, tolerance):
    """A streamed frame's rotations ``(P, J, 4)`` normalised, and what is wrong with it: ``(0, ...)``
    nothing; ``(1, performer, 0, 0.0)`` a non-finite number; ``(2, performer, joint, norm)`` a
    quaternion whose norm is more than ``tolerance`` off 1."""
    out = np.empty_like(rotations)
    for r in range(rotations.shape[0]):
        finite = math.isfinite(roots[r, 0]) and math.isfinite(roots[r, 1]) and math.isfinite(roots[r, 2])
        for j in range(rotations.shape[1]):
            for c in range(4):
                finite = finite and math.isfinite(rotations[r, j, c])
        if not finite:
            return out, 1, r, 0, 0.0
    for r in range(rotations.shape[0]):
        for j in range(rotations.shape[1]):
            q = rotations[r, j]
            n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
            if abs(n - 1.0) > tolerance:
                return out, 2, r, j, n
            for c in range(4):
                out[r, j, c] = q[c] / n
    return out, 0, 0, 0, 0.0


@njit(cache=True)
def slerp_rows(a, b, t):
    """``rotations.slerp`` of rows: quaternions ``(N, 4)`` twice, fractions ``(N,)``."""
    out = np.empty_like(a)
    for r in range(a.shape[0]):
        dot = a[r, 0] * b[r, 0] + a[r, 1] * b[r, 1] + a[r, 2] * b[r, 2] + a[r, 3] * b[r, 3]
        flip = -1.0 if dot < 0.0 else 1.0
        theta = math.acos(min(max(abs(dot), -1.0), 1.0))
        sin = math.sin(theta)
        if sin < 1e-6:
            wa, wb = 1.0 - t[r], t[r]
        else:
            wa, wb = math.sin((1.0 - t[r]) * theta) / sin, math.sin(t[r] * theta) / sin
        n2 = 0.0
        for c in range(4):
            out[r, c] = wa * a[r, c] + wb * flip * b[r, c]
            n2 += out[r, c] * out[r, c]
        n = max(math.sqrt(n2), _EPS)
        for c in range(4):
            out[r, c] /= n
    return out


@njit(cache=True)
def hermite_rotations(q0, r0, r1, b, cd):
    """``q0 exp(b r0 + cd r1)`` of rows (``resample.Hermite``): quaternions ``(N, 4)`` and
    rotation vectors ``(N, 3)`` twice."""
    out = np.empty_like(q0)
    e = np.empty(4)
    for r in range(q0.shape[0]):
        v0 = b * r0[r, 0] + cd * r1[r, 0]
        v1 = b * r0[r, 1] + cd * r1[r, 1]
        v2 = b * r0[r, 2] + cd * r1[r, 2]
        angle = _norm3(v0, v1, v2)
        scale = 0.5 if angle < 1e-9 else math.sin(0.5 * angle) / max(angle, 1e-12)  # rotations.exp
        e[0], e[1], e[2], e[3] = math.cos(0.5 * angle), scale * v0, scale * v1, scale * v2
        _qmul(q0[r], e, out[r])
    return out


@njit(cache=True)
def _log_between(q0, q1, ratio, out) -> None:
    """``ratio * rotations.log(conjugate(q0) * q1)``: the rotation vector from ``q0`` to ``q1``
    (short arc), scaled, into ``out`` (3,)."""
    q = np.empty(4)
    _local(q0, q1, q)
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), _EPS)
    sign = -1.0 if q[0] / n < 0.0 else 1.0
    w, x, y, z = sign * q[0] / n, sign * q[1] / n, sign * q[2] / n, sign * q[3] / n
    s = _norm3(x, y, z)
    scale = 2.0 if s < 1e-9 else 2.0 * math.atan2(s, w) / max(s, 1e-12)
    out[0], out[1], out[2] = ratio * scale * x, ratio * scale * y, ratio * scale * z


@njit(cache=True)
def hermite_tangents(q0, q1, qp, ratio):
    """The rotation vectors of ``resample.Hermite``'s segment from ``q0`` to ``q1`` (rows ``(N,
    4)``): to ``q1``, and ``-ratio`` times the one to the frame before, ``qp``, ``(N, 3)`` each."""
    r1 = np.empty((q0.shape[0], 3))
    r0 = np.empty((q0.shape[0], 3))
    for r in range(q0.shape[0]):
        _log_between(q0[r], q1[r], 1.0, r1[r])
        _log_between(q0[r], qp[r], -ratio, r0[r])
    return r1, r0


# --- JointState layout (io.joint_state): core frame <-> REP-103 Euler angles ----------------------
# REP-103 (x, y, z) are the core's (z, x, y); a rotation maps with its axis.


@njit(cache=True)
def _ros_euler(q, out, at) -> None:
    """Intrinsic X-Y-Z Euler angles (``rotations.to_euler(q, "XYZ")``) of the core quaternion
    ``q`` turned into REP-103 axes, into ``out[at:at + 3]``."""
    ros = np.empty(4)
    ros[0], ros[1], ros[2], ros[3] = q[0], q[3], q[1], q[2]
    m00, m01, m02, _, m11, m12, _, m21, m22 = _entries(ros)
    cos_b = math.hypot(m00, m01)
    out[at + 1] = math.atan2(m02, cos_b)
    if cos_b < 1e-7:  # gimbal lock: the third angle 0, the first takes the whole turn
        out[at], out[at + 2] = math.atan2(m21, m11), 0.0
    else:
        out[at], out[at + 2] = math.atan2(-m12, m22), math.atan2(-m01, m00)


@njit(cache=True)
def _ros_quat(angles, at, q) -> None:
    """The inverse of :func:`_ros_euler`: ``Rx @ Ry @ Rz`` of ``angles[at:at + 3]`` as a core
    quaternion ``q``."""
    ca, sa = math.cos(0.5 * angles[at]), math.sin(0.5 * angles[at])
    cb, sb = math.cos(0.5 * angles[at + 1]), math.sin(0.5 * angles[at + 1])
    cc, sc = math.cos(0.5 * angles[at + 2]), math.sin(0.5 * angles[at + 2])
    w, x, y, z = ca * cb, sa * cb, ca * sb, sa * sb  # Rx @ Ry, then @ Rz:
    rw, rx, ry, rz = w * cc - z * sc, x * cc + y * sc, y * cc - x * sc, z * cc + w * sc
    q[0], q[1], q[2], q[3] = rw, ry, rz, rx


@njit(cache=True)
def euler_rows(quats):
    """:func:`_ros_euler` of every row of ``quats (N, 4)``: ``(N, 3)``."""
    out = np.empty((quats.shape[0], 3))
    for r in range(quats.shape[0]):
        _ros_euler(quats[r], out[r], 0)
    return out


@njit(cache=True)
def quat_rows(angles):
    """:func:`_ros_quat` of every row of ``angles (N, 3)``: ``(N, 4)``."""
    out = np.empty((angles.shape[0], 4))
    for r in range(angles.shape[0]):
        _ros_quat(angles[r], 0, out[r])
    return out


@njit(cache=True)
def layout_values(rotations, roots, pelvis):
    """The default JointState layout of poses (rows of ``rotations (F, J, 4)``, ``roots (F, 3)``):
    the pelvis position in REP-103 axes, its world orientation (the static root's rotation times
    the pelvis's), then every joint below it, three angles each: ``(F, 3 + 3 (J - pelvis))``."""
    n_joints = rotations.shape[1]
    out = np.empty((rotations.shape[0], 3 + 3 * (n_joints - pelvis)))
    hips = np.empty(4)
    for f in range(rotations.shape[0]):
        out[f, 0], out[f, 1], out[f, 2] = roots[f, 2], roots[f, 0], roots[f, 1]
        _qmul(rotations[f, 0], rotations[f, pelvis], hips)
        _ros_euler(hips, out[f], 3)
        for j in range(pelvis + 1, n_joints):
            _ros_euler(rotations[f, j], out[f], 3 + 3 * (j - pelvis))
    return out


@njit(cache=True)
def layout_poses(values, pelvis):
    """The inverse of :func:`layout_values`: local rotations ``(F, J, 4)`` (the joints above the
    pelvis identity, the pelvis its world orientation) and roots ``(F, 3)``."""
    n_joints = pelvis + (values.shape[1] - 3) // 3
    rotations = np.zeros((values.shape[0], n_joints, 4))
    roots = np.empty((values.shape[0], 3))
    for f in range(values.shape[0]):
        roots[f, 0], roots[f, 1], roots[f, 2] = values[f, 1], values[f, 2], values[f, 0]
        for j in range(pelvis):
            rotations[f, j, 0] = 1.0
        for j in range(pelvis, n_joints):
            _ros_quat(values[f], 3 + 3 * (j - pelvis), rotations[f, j])
    return rotations, roots
