"""The generative measures of the ESANN 2018 seed (its Tables 1a and 1b), numpy only, on windows
flattened to vectors:

- :func:`parzen_log_likelihood`: the mean log-likelihood of test windows under a Gaussian Parzen
  window estimator fitted on generated windows (Goodfellow et al. 2014's protocol, which the paper
  follows), with its standard error; :func:`parzen_bandwidth` picks the kernel width on validation
  windows, as that protocol does.
- :func:`g2t` and :func:`t2g`: the mean distance from each generated window to its nearest true
  window (realism: low when every generated window looks like some real one) and from each true
  window to its nearest generated one (coverage: low when no real mode is missed).

:func:`as_vectors` turns windows of frames into the vectors these compare (normalised per channel
by given statistics, so that no block of features outweighs the others by its units).
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.errors import MotionStyleError

BATCH = 512  # rows per block of pairwise distances (memory: BATCH x len(other) floats)


def as_vectors(windows: np.ndarray, mean: np.ndarray | None = None, std: np.ndarray | None = None
               ) -> np.ndarray:
    """``(N, T, C)`` windows -> ``(N, T * C)`` float64 vectors, each channel ``(x - mean) / std``
    when given (``(C,)``)."""
    w = np.asarray(windows, dtype=np.float64)
    if w.ndim != 3:
        raise MotionStyleError(f"windows of shape {w.shape}; expected (N, T, C)")
    if mean is not None:
        w = w - np.asarray(mean, dtype=np.float64)
    if std is not None:
        w = w / np.asarray(std, dtype=np.float64)
    return w.reshape(len(w), -1)


def _check(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or not len(a) or not len(b):
        raise MotionStyleError(f"vectors of shapes {a.shape} and {b.shape}; expected (N, D) and (M, D), "
                               "neither empty")
    return a, b


def _squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(len(a), len(b))`` squared Euclidean distances (clamped at 0 against rounding)."""
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None] - 2.0 * a @ b.T
    return np.maximum(d, 0.0)


def parzen_log_likelihood(test: np.ndarray, samples: np.ndarray, sigma: float) -> tuple[float, float]:
    """Mean log-likelihood of the ``test`` vectors ``(N, D)`` under an isotropic Gaussian kernel
    density of width ``sigma`` on the ``samples`` ``(M, D)``, and its standard error over the test
    vectors (the paper's +-): ``log p(x) = logsumexp_j(-|x - s_j|^2 / 2 sigma^2) - log M - D/2
    log(2 pi sigma^2)``."""
    test, samples = _check(test, samples)
    if not (np.isfinite(sigma) and sigma > 0):
        raise MotionStyleError(f"sigma must be a positive number, got {sigma!r}")
    d = test.shape[1]
    out = np.empty(len(test))
    for start in range(0, len(test), BATCH):
        e = -_squared_distances(test[start : start + BATCH], samples) / (2.0 * sigma**2)
        top = e.max(axis=1, keepdims=True)
        out[start : start + BATCH] = top[:, 0] + np.log(np.exp(e - top).sum(axis=1))
    out += -np.log(len(samples)) - 0.5 * d * np.log(2.0 * np.pi * sigma**2)
    sem = float(out.std(ddof=1) / np.sqrt(len(out))) if len(out) > 1 else 0.0
    return float(out.mean()), sem


def parzen_bandwidth(validation: np.ndarray, samples: np.ndarray,
                     sigmas: np.ndarray | None = None) -> float:
    """The kernel width among ``sigmas`` (default: 20 from 0.05 to 5, log-spaced) under which the
    ``validation`` vectors are likeliest: the width to use on the test vectors."""
    grid = np.geomspace(0.05, 5.0, 20) if sigmas is None else np.asarray(sigmas, dtype=np.float64)
    scores = [parzen_log_likelihood(validation, samples, float(s))[0] for s in grid]
    return float(grid[int(np.argmax(scores))])


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(len(a),)``: each vector of ``a``'s Euclidean distance to its nearest vector of ``b``."""
    a, b = _check(a, b)
    return np.concatenate([np.sqrt(_squared_distances(a[s : s + BATCH], b).min(axis=1))
                           for s in range(0, len(a), BATCH)])


def g2t(generated: np.ndarray, true: np.ndarray) -> float:
    """Generated to true: the mean distance from each generated vector to its nearest true one."""
    return float(nearest_distances(generated, true).mean())


def t2g(generated: np.ndarray, true: np.ndarray) -> float:
    """True to generated: the mean distance from each true vector to its nearest generated one."""
    return float(nearest_distances(true, generated).mean())
