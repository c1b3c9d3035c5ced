"""Trajectory chunks: the frames' spacing, angles unwrapped across chunks, velocities that are the
positions' central differences (none on a chunk's last point by default), early chunks at gaps."""

import numpy as np
import pytest

from motion_style_ros.runtime.trajectory import Chunker

PERIOD = 33_333_333


def frames(n, start=0):
    t = (start + np.arange(n)) * PERIOD * 1e-9
    return [(start * PERIOD + k * PERIOD, np.array([np.sin(tk), 3.0 * tk])) for k, tk in enumerate(t)]


def run(chunker, stream):
    return [c for stamp, p in stream for c in chunker.add(stamp, p)]


def test_inner_velocities_are_central_differences_and_the_last_point_has_none():
    chunker = Chunker(4, PERIOD, 0.5)
    chunks = run(chunker, frames(12))
    assert len(chunks) == 3 and all(len(c.positions) == 4 for c in chunks)
    assert all(c.times_ns == [PERIOD, 2 * PERIOD, 3 * PERIOD, 4 * PERIOD] for c in chunks)
    assert all(c.velocities[-1] is None for c in chunks)
    p = np.concatenate([c.positions for c in chunks])
    v = [v for c in chunks for v in c.velocities]
    dt = PERIOD * 1e-9
    for k in range(1, 11):
        if v[k] is not None:
            np.testing.assert_allclose(v[k], (p[k + 1] - p[k - 1]) / (2 * dt), rtol=1e-9)
    np.testing.assert_allclose(v[0], (p[1] - p[0]) / dt, rtol=1e-9)  # the stream's first: forward
    assert v[4] is not None  # a chunk's first point: central, with the previous chunk's last


def test_all_and_none():
    last = run(Chunker(4, PERIOD, 0.5, "all"), frames(4))[0]
    p = last.positions
    np.testing.assert_allclose(last.velocities[-1], (p[-1] - p[-2]) / (PERIOD * 1e-9), rtol=1e-9)
    assert all(v is None for v in run(Chunker(4, PERIOD, 0.5, "none"), frames(4))[0].velocities)
    with pytest.raises(ValueError, match="inner, all, none"):
        Chunker(4, PERIOD, 0.5, "some")


def test_angles_are_unwrapped_across_chunks_and_a_gap_sends_the_chunk_early():
    chunker = Chunker(3, PERIOD, 0.5)
    chunker.clear(np.array([True]))
    stream = [(k * PERIOD, np.array([np.mod(3.0 + 0.2 * k + np.pi, 2 * np.pi) - np.pi])) for k in range(6)]
    chunks = run(chunker, stream)
    unwrapped = np.concatenate([c.positions[:, 0] for c in chunks])
    np.testing.assert_allclose(np.diff(unwrapped), 0.2, atol=1e-12)
    gap = run(chunker, [(6 * PERIOD, np.array([0.1])), (6 * PERIOD + 10**9, np.array([0.2]))])
    assert len(gap) == 1 and len(gap[0].positions) == 1 and gap[0].velocities == [None]
    assert [len(c.positions) for c in chunker.flush()] == [1]
