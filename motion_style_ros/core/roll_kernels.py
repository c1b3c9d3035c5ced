"""The compiled rows of the arm-roll conformance (:mod:`~motion_style_ros.core.conform`): the arms'
moments, when a roll is due, its solve and easing, and the rolls applied
(:mod:`~motion_style_ros.core.jit` says why compiled)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from motion_style_ros.core.jit import norm3, qmul, quat_matrix


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
            if not -b1 > hang_cos * max(norm3(b0, b1, b2), 1e-9):
                continue
            for i in range(side * per_arm, (side + 1) * per_arm):
                quat_matrix(rotations[r, joints[i]], m)
                v = m.ravel()
                for a in range(9):
                    first[r, i, a] += v[a]
                    for b in range(9):
                        second[r, i, a, b] += v[a] * v[b]
                count[r, i] += 1.0


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
            qmul(out[r, j], roll, q)
            if i % per_arm:
                half = 0.5 * sign * angles[r, i - 1]
                before[0], before[1], before[2], before[3] = math.cos(half), math.sin(half), 0.0, 0.0
                qmul(before, q, out[r, j])
            else:
                out[r, j] = q
    return out
