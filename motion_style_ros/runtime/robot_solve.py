"""The bounded least-squares solve of :class:`~motion_style_ros.runtime.robot_target.RobotTarget`:
a projected Levenberg-Marquardt on residuals with an analytic Jacobian, or
``scipy.optimize.least_squares`` as the reference.

Why this solver
---------------
The problem is small (one unknown per actuated joint plus the base height, about 120 residuals)
with an analytic Jacobian (each joint's axis crossed with the lever arm), so a projected
Levenberg-Marquardt written here for it (free variables solved, variables at a bound that the
gradient pushes outwards held) converges in 2-4 iterations from the previous frame, at well under
a millisecond of numpy per frame. ``scipy.optimize.least_squares`` (``solver="scipy"``, method
``trf`` with the same bounds, residuals and Jacobian) reaches the same costs but spends several
milliseconds per frame in its own bookkeeping, too much for a 120 Hz node; it stays available as the
reference. An IK library (ikpy, pink/pinocchio) was considered: they solve end-effector pose
targets, whereas what keeps a motion's character on another body is bone *directions* plus feet,
and they would add a dependency (pinocchio is a large compiled one) without saving the Jacobian,
which is a dozen lines (``RobotTarget._residuals``). They would not pay for themselves.
"""

from __future__ import annotations

from typing import Callable

import numpy as np


def solve(residuals: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], x0: np.ndarray,
          lo: np.ndarray, hi: np.ndarray, iters: int, method: str = "lm") -> np.ndarray:
    """``x`` within ``[lo, hi]`` minimising ``|r(x)|^2``, ``residuals(x) -> (r, jacobian)``,
    from ``x0`` (clipped to the bounds) in at most ``iters`` iterations; ``method``: ``"lm"``
    (free variables solved, variables at a bound that the gradient pushes outwards held) or
    ``"scipy"`` (``least_squares``, ``trf``, up to ``4 * iters`` evaluations)."""
    x = np.clip(x0, lo, hi)
    if method == "scipy":
        from scipy.optimize import least_squares

        cache = {}

        def both(v):
            key = v.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = residuals(v)
            return cache[key]

        inside = np.clip(x, np.nextafter(lo, hi), np.nextafter(hi, lo))
        res = least_squares(lambda v: both(v)[0], inside, jac=lambda v: both(v)[1],
                            bounds=(lo, hi), method="trf", max_nfev=iters * 4,
                            xtol=1e-6, ftol=1e-6)
        return np.clip(res.x, lo, hi)
    r, jac = residuals(x)
    cost = r @ r
    lam = 1e-3
    for _ in range(iters):
        g = jac.T @ r
        hess = jac.T @ jac
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        hf = hess[np.ix_(free, free)]
        hf[np.diag_indices_from(hf)] += lam * (1.0 + np.diag(hf))
        step = np.zeros_like(x)
        step[free] = -np.linalg.solve(hf, g[free])
        xn = np.clip(x + step, lo, hi)
        rn, jn = residuals(xn)
        cn = rn @ rn
        if cn < cost:
            done = np.abs(xn - x).max() < 1e-3 or (lam < 1e-2 and cost - cn < 1e-6 * (1.0 + cost))
            x, r, jac, cost = xn, rn, jn, cn
            lam = max(lam * 0.3, 1e-7)
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e4:
                break
    return x
