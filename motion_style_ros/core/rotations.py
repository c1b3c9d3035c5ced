"""Batched rotation maths on numpy arrays.

Quaternions are ``(..., 4)`` arrays in ``(w, x, y, z)`` order (scalar first, as in ROS messages and
BVH-tooling conventions); they rotate column vectors: ``v' = q * v * q^-1``. Every function
broadcasts over leading axes so a whole clip ``(T, J, 4)`` is one call (SciPy's ``Rotation``, the
reference the tests check against, costs more per call than a streamed frame affords).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from motion_style_ros.core import jit


_EPS = 1e-12


def identity(shape: tuple[int, ...] = (), dtype=np.float64) -> np.ndarray:
    """Identity quaternions of the given leading shape."""
    q = np.zeros(tuple(shape) + (4,), dtype=dtype)
    q[..., 0] = 1.0
    return q


def norm(v: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """Euclidean length along the last axis (``np.linalg.norm``'s checks cost more than the maths
    on the small arrays of one streamed frame)."""
    return np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=keepdims))


def normalize(q: np.ndarray) -> np.ndarray:
    return q / np.maximum(norm(q, keepdims=True), _EPS)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)


inverse = conjugate


# Up to this many quaternions in a call, matrix forms (a few numpy calls) beat the elementwise
# ones (a few dozen calls, fewer operations): that is what one streamed frame costs.
_SMALL = 256

# Hamilton product as a matrix: a * b = (a[_LEFT] * _LEFT_SIGN) @ b.
_LEFT = np.array([[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]])
_LEFT_SIGN = np.array([[1.0, -1.0, -1.0, -1.0], [1.0, 1.0, -1.0, 1.0], [1.0, 1.0, 1.0, -1.0],
                       [1.0, -1.0, 1.0, 1.0]])


def _small(a: np.ndarray, b: np.ndarray) -> bool:
    """Both hold at most :data:`_SMALL` vectors (no views made: this runs on every product)."""
    return a.size <= _SMALL * a.shape[-1] and b.size <= _SMALL * b.shape[-1]


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``)."""
    if _small(a, b):
        return (a[..., _LEFT] * _LEFT_SIGN @ b[..., None])[..., 0]
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4)."""
    if _small(q, v):
        return (to_matrix(q) @ v[..., None])[..., 0]
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


_NEXT_AFTER, _AFTER_NEXT = np.array([1, 2, 0, 2, 0, 1]), np.array([2, 0, 1, 1, 2, 0])
_CHANNELS = np.arange(3)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of 3-vectors, same numbers; np.cross's axis handling costs more than the maths
    on the small arrays of one streamed frame (both products in one multiplication)."""
    products = a[..., _NEXT_AFTER] * b[..., _AFTER_NEXT]
    return products[..., :3] - products[..., 3:]


def _matrix_table() -> np.ndarray:
    """``(16, 9)``: the rotation matrix of a unit quaternion as a quadratic form, ``(q q^T) @ T``."""
    terms = {  # matrix entry (row, col): [(i, j, coefficient of q_i q_j)]
        (0, 0): [(0, 0, 1), (1, 1, 1), (2, 2, -1), (3, 3, -1)],
        (0, 1): [(1, 2, 2), (0, 3, -2)], (0, 2): [(1, 3, 2), (0, 2, 2)],
        (1, 0): [(1, 2, 2), (0, 3, 2)], (1, 1): [(0, 0, 1), (1, 1, -1), (2, 2, 1), (3, 3, -1)],
        (1, 2): [(2, 3, 2), (0, 1, -2)], (2, 0): [(1, 3, 2), (0, 2, -2)],
        (2, 1): [(2, 3, 2), (0, 1, 2)], (2, 2): [(0, 0, 1), (1, 1, -1), (2, 2, -1), (3, 3, 1)],
    }
    table = np.zeros((4, 4, 3, 3))
    for (row, col), products in terms.items():
        for i, j, c in products:
            table[i, j, row, col] = c
    return table.reshape(16, 9)


_MATRIX = _matrix_table()


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)``; one matrix product, so one frame costs a few numpy calls."""
    q = normalize(q)
    outer = (q[..., :, None] * q[..., None, :]).reshape(q.shape[:-1] + (16,))
    return (outer @ _MATRIX).reshape(q.shape[:-1] + (3, 3))


def _outer_table() -> tuple[np.ndarray, np.ndarray]:
    """``(9, 16)`` and ``(16,)``: ``4 q q^T`` of a rotation matrix's quaternion, linear in the matrix."""
    entries = {  # (i, j) of 4 q q^T: [(matrix row, col, coefficient)], plus a constant
        (0, 0): [(0, 0, 1), (1, 1, 1), (2, 2, 1)], (1, 1): [(0, 0, 1), (1, 1, -1), (2, 2, -1)],
        (2, 2): [(0, 0, -1), (1, 1, 1), (2, 2, -1)], (3, 3): [(0, 0, -1), (1, 1, -1), (2, 2, 1)],
        (0, 1): [(2, 1, 1), (1, 2, -1)], (0, 2): [(0, 2, 1), (2, 0, -1)],
        (0, 3): [(1, 0, 1), (0, 1, -1)], (1, 2): [(0, 1, 1), (1, 0, 1)],
        (1, 3): [(0, 2, 1), (2, 0, 1)], (2, 3): [(1, 2, 1), (2, 1, 1)],
    }
    table, const = np.zeros((3, 3, 4, 4)), np.zeros((4, 4))
    for (i, j), terms in entries.items():
        for row, col, c in terms:
            table[row, col, i, j] = table[row, col, j, i] = c
    const[np.diag_indices(4)] = 1.0
    return table.reshape(9, 16), const.reshape(16)


_OUTER, _OUTER_CONST = _outer_table()
_DIAGONAL = np.arange(4)


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Quaternions (w >= 0) from rotation matrices ``(..., 3, 3)``.

    ``4 q q^T`` is linear in the matrix; its column with the largest diagonal entry is the
    best-conditioned multiple of ``q`` (Shepperd's method, in a few numpy calls).
    """
    lead = m.shape[:-2]
    outer = (m.reshape(lead + (9,)) @ _OUTER + _OUTER_CONST).reshape(lead + (4, 4))
    rows = outer.reshape(-1, 4, 4)  # symmetric: row ``best`` is column ``best``
    best = np.argmax(rows[:, _DIAGONAL, _DIAGONAL], axis=-1)
    q = rows[np.arange(len(rows)), best].reshape(lead + (4,))
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    return normalize(q)


def from_euler(angles: np.ndarray, order: str, degrees: bool = False) -> np.ndarray:
    """Quaternions from intrinsic Euler angles as written in BVH channel order.

    ``order`` names the axes in the order the channels are listed (for example ``"ZXY"``); the
    rotation is ``R = R_order[0] @ R_order[1] @ R_order[2]``, which is what BVH files mean.
    """
    order = order.upper()
    angles = np.asarray(angles, dtype=np.float64)
    if degrees:
        angles = np.deg2rad(angles)
    half = 0.5 * angles
    q = np.zeros(angles.shape + (4,))  # one rotation per channel
    q[..., 0] = np.cos(half)
    q[..., _CHANNELS, [1 + "XYZ".index(axis) for axis in order]] = np.sin(half)
    return multiply(multiply(q[..., 0, :], q[..., 1, :]), q[..., 2, :])


def to_euler(q: np.ndarray, order: str, degrees: bool = False) -> np.ndarray:
    """Intrinsic Euler angles in ``order`` (inverse of :func:`from_euler`), any of the six
    Tait-Bryan orders BVH files use; the middle angle in [-90, 90] degrees.

    Read off the rotation matrix (a few numpy calls: a streamed JointState frame converts 21
    joints, where SciPy's per-call overhead cost more than the maths). At gimbal lock the third
    angle is 0 and the first takes the whole turn, as SciPy does.
    """
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"Euler order {order!r}: expected a permutation of XYZ")
    i, j, k = ("XYZ".index(a) for a in order)
    e = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 for the cyclic orders XYZ, YZX, ZXY
    m = to_matrix(q)
    cos_b = np.hypot(m[..., i, i], m[..., i, j])
    b = np.arctan2(e * m[..., i, k], cos_b)
    locked = cos_b < 1e-7
    a = np.where(locked, np.arctan2(e * m[..., k, j], m[..., j, j]),
                 np.arctan2(-e * m[..., j, k], m[..., k, k]))
    c = np.where(locked, 0.0, np.arctan2(-e * m[..., i, j], m[..., i, i]))
    angles = np.stack([a, b, c], axis=-1)
    return np.rad2deg(angles) if degrees else angles


def from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.maximum(norm(axis, keepdims=True), _EPS)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def from_yaw(yaw: np.ndarray) -> np.ndarray:
    """Rotation about +Y (the up axis of the motion core)."""
    half = 0.5 * np.asarray(yaw, dtype=np.float64)
    q = np.zeros(half.shape + (4,))
    q[..., 0] = np.cos(half)
    q[..., 2] = np.sin(half)
    return q


def between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking direction ``u`` onto direction ``v``."""
    u = u / np.maximum(norm(u, keepdims=True), _EPS)
    v = v / np.maximum(norm(v, keepdims=True), _EPS)
    w = 1.0 + np.add.reduce(u * v, axis=-1, keepdims=True)
    xyz = cross(u, v)
    opposite = w[..., 0] < 1e-9
    if np.any(opposite):  # 180 degrees: turn about any axis orthogonal to u
        u_b = np.broadcast_to(u, xyz.shape)
        ortho = cross(u_b, np.eye(3)[np.argmin(np.abs(u_b), axis=-1)])
        xyz = np.where(opposite[..., None], ortho, xyz)
    return normalize(np.concatenate([w, xyz], axis=-1))


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians, in [0, pi]."""
    w = np.abs(normalize(q)[..., 0])
    return 2.0 * np.arccos(np.clip(w, -1.0, 1.0))


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Geodesic angle between two rotations, in radians."""
    return angle(multiply(conjugate(a), b))


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation along the short arc; ``t`` broadcasts over the leading axes
    (:func:`slerp_rows`)."""
    a, b, t = (np.asarray(x, dtype=np.float64) for x in (a, b, t))
    lead = np.broadcast_shapes(a.shape[:-1], b.shape[:-1], t.shape)

    def rows(x: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        return jit.rows(np.broadcast_to(x, shape)).reshape((-1,) + shape[len(lead):])

    return slerp_rows(rows(a, lead + (4,)), rows(b, lead + (4,)), rows(t, lead)).reshape(lead + (4,))


def log(q: np.ndarray) -> np.ndarray:
    """Rotation vector (axis times angle, radians) of the short arc; the inverse of :func:`exp`."""
    q = normalize(q)
    q = np.where(q[..., :1] < 0, -q, q)
    s = norm(q[..., 1:], keepdims=True)
    half = np.arctan2(s, q[..., :1])
    # angle / sin(angle / 2), with its limit 2 near the identity
    scale = np.where(s < 1e-9, 2.0, 2.0 * half / np.maximum(s, 1e-12))
    return scale * q[..., 1:]


def exp(v: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation vector ``(..., 3)`` (axis times angle)."""
    angle = norm(v, keepdims=True)
    # sin(angle / 2) / angle, with its limit 1/2 near zero
    scale = np.where(angle < 1e-9, 0.5, np.sin(0.5 * angle) / np.maximum(angle, 1e-12))
    return np.concatenate([np.cos(0.5 * angle), scale * v], axis=-1)


def make_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in the same hemisphere."""
    q = np.moveaxis(np.array(q, copy=True), axis, 0)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.cumsum(dots < 0, axis=0) % 2
    q[1:] *= np.where(flips[..., None] == 1, -1.0, 1.0)
    return np.moveaxis(q, 0, axis)


_FIRST_COLUMNS = _MATRIX[:, [0, 3, 6, 1, 4, 7]]  # the table's entries of matrix columns 0 and 1


def to_6d(q: np.ndarray) -> np.ndarray:
    """Continuous 6D representation (Zhou et al. 2019): the first two matrix columns."""
    q = normalize(q)
    return (q[..., :, None] * q[..., None, :]).reshape(q.shape[:-1] + (16,)) @ _FIRST_COLUMNS


def matrix_from_6d(d6: np.ndarray) -> np.ndarray:
    """Gram-Schmidt back to a rotation matrix; any 6-vector with independent halves is valid."""
    a = d6[..., :3]
    b = d6[..., 3:6]
    x = a / np.maximum(norm(a, keepdims=True), _EPS)
    b = b - np.add.reduce(x * b, axis=-1, keepdims=True) * x
    y = b / np.maximum(norm(b, keepdims=True), _EPS)
    m = np.empty(x.shape + (3,))
    m[..., 0], m[..., 1], m[..., 2] = x, y, cross(x, y)
    return m


def from_6d(d6: np.ndarray) -> np.ndarray:
    return from_matrix(matrix_from_6d(d6))


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
