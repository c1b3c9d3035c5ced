"""The compiled rows of :mod:`~motion_style_ros.core.features`: the encoding of poses into the
models' features and back, the root's trajectory, and a stream's pull towards its performer
(:mod:`~motion_style_ros.core.jit` says why compiled)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from motion_style_ros.core.jit import (
    EPS,
    facing_angle,
    fk_row,
    norm3,
    qmul,
    quat_entries,
    quat_matrix,
    rest_pose,
    wrap_angle,
)


@njit(cache=True)
def facing_yaw(g_pos, across):
    """:func:`facing_angle` of poses ``(N, J, 3)``."""
    yaw = np.empty(g_pos.shape[0])
    for r in range(g_pos.shape[0]):
        yaw[r] = facing_angle(g_pos[r], across)
    return yaw


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
        rest_pose(offsets, pelvis, roots[r], positions)
        fk_row(parents, rotations[r], positions, g_rot, g_pos)
        yaw = facing_angle(g_pos, across)
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
    quat_matrix(inv, m)  # into the facing frame
    gx, gz = g_pos[pelvis, 0], g_pos[pelvis, 2]
    px, pz = prev_g_pos[pelvis, 0], prev_g_pos[pelvis, 2]
    vx, vz = (gx - px) * fps, (gz - pz) * fps
    out[0] = m[0, 0] * vx + m[0, 2] * vz
    out[1] = m[2, 0] * vx + m[2, 2] * vz
    out[2] = g_pos[pelvis, 1]
    out[3] = wrap_angle(yaw - prev_yaw) * fps
    for i in range(k):
        j = joints[i]
        if i == 0:  # the pelvis relative to the facing frame
            qmul(inv, pelvis_rot, q)
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
        speed = norm3(g_pos[f, 0] - prev_g_pos[f, 0], g_pos[f, 1] - prev_g_pos[f, 1],
                       g_pos[f, 2] - prev_g_pos[f, 2]) * fps
        out[contact + i] = 1.0 if (g_pos[f, 1] < heights[i] and speed < contact_speed) else 0.0


@njit(cache=True)
def _six(q, out, at) -> None:
    """``rotations.to_6d``: the first two columns of ``q``'s matrix into ``out[at:at + 6]``."""
    m00, m01, _, m10, m11, _, m20, m21, _ = quat_entries(q)
    out[at], out[at + 1], out[at + 2] = m00, m10, m20
    out[at + 3], out[at + 4], out[at + 5] = m01, m11, m21


@njit(cache=True)
def _from_6d(d, at, q) -> None:
    """``rotations.from_6d`` of ``d[at:at + 6]`` into ``q``: Gram-Schmidt to a matrix, then the
    best-conditioned column of ``4 q q^T`` (Shepperd), ``w >= 0``, normalised."""
    a0, a1, a2 = d[at], d[at + 1], d[at + 2]
    b0, b1, b2 = d[at + 3], d[at + 4], d[at + 5]
    na = max(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), EPS)
    x0, x1, x2 = a0 / na, a1 / na, a2 / na
    dot = x0 * b0 + x1 * b1 + x2 * b2
    b0, b1, b2 = b0 - dot * x0, b1 - dot * x1, b2 - dot * x2
    nb = max(math.sqrt(b0 * b0 + b1 * b1 + b2 * b2), EPS)
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
    n = max(math.sqrt(w * w + x * x + y * y + z * z), EPS)
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
            qmul(turn, local, rotations[pelvis])
        else:
            rotations[joints[i]] = local
    root[0] = ground[0]
    root[1] = ground[1] + f[2]
    root[2] = ground[2]


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
        yaw[r] += gain * wrap_angle(to_yaw[r] - yaw[r])
