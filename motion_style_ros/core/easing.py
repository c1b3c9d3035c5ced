"""Easing for blends that start and stop without a kink (a linear fade jerks the motion at both ends)."""

from __future__ import annotations

import numpy as np


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 -> 1 with zero slope at both ends (no kink when a blend starts or ends)."""
    x = np.minimum(np.maximum(x, 0.0), 1.0)  # np.clip's overhead is most of a streamed frame's cost
    return x * x * (3.0 - 2.0 * x)
