"""A performer's size from their stream: the scale estimate, the maps in and out, the session."""

import numpy as np

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.proportions import CONTACTS, StreamScale, clip_scale
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.evaluation.live import scaled, stream
from motion_style_ros.io import bvh
from motion_style_ros.runtime.recurrent import RecurrentSession


def stream_scale(motion: Motion) -> list[float]:
    """The applied scale after each frame of ``motion`` streamed through a StreamScale."""
    sk = motion.skeleton
    contacts = [sk.index(n) for n in CONTACTS]
    scale = StreamScale(1, motion.fps)
    g = motion.global_positions()
    relative = g[:, contacts] - g[:, sk.pelvis, None]
    estimates = []
    for t in range(motion.n_frames):
        scale.to_canonical(motion.root_positions[t:t + 1])
        scale.observe(relative[t:t + 1])
        estimates.append(float(scale.scale[0]))
    return estimates


def test_a_walk_from_a_smaller_or_larger_performer_is_measured():
    walk = synthetic_motion("walk", 30.0, 6.0)
    base = clip_scale(walk)  # the procedural walk's own (its feet slide a little: 0.85)
    assert 0.7 < base < 1.1
    for size in (0.8, 1.25):
        assert abs(clip_scale(scaled(walk, size)) / base - size) < 0.02
        live = stream_scale(scaled(walk, size))
        assert abs(live[30] / base / size - 1.0) < 0.1, live[30]  # after a second
        assert abs(live[-1] / base / size - 1.0) < 0.02


def test_motion_without_steps_keeps_the_canonical_size():
    wave = synthetic_motion("wave", 30.0, 6.0)
    assert clip_scale(scaled(wave, 0.7)) == 1.0 or abs(clip_scale(scaled(wave, 0.7)) - 1.0) < 0.02
    assert abs(stream_scale(scaled(wave, 0.7))[-1] - 1.0) < 0.02


def test_the_maps_in_and_out_are_inverse_and_continuous_while_the_scale_moves():
    scale = StreamScale(2, 30.0)
    rng = np.random.default_rng(0)
    roots = np.cumsum(rng.normal(0.0, 0.05, (60, 2, 3)), axis=0) + [0.0, 0.9, 0.0]
    scale.target[:] = [0.8, 1.3]
    previous = None
    for t in range(60):
        canonical_root = scale.to_canonical(roots[t])
        assert np.allclose(scale.to_stream(canonical_root), roots[t])  # the frame maps back
        if t == 0:
            assert np.allclose(canonical_root, roots[0])  # a stream starts where it is
        if previous is not None:  # displacements divided by the scale as it stands
            step = (roots[t] - roots[t - 1]) / scale.scale[:, None]
            assert np.allclose(canonical_root - previous, step)
        previous = canonical_root
        scale.scale = scale.scale + 0.2 * (scale.target - scale.scale)  # as observe() eases it


def test_a_cmu_walk_from_a_smaller_performer_keeps_their_stride(datasets):
    walk = retarget(bvh.read(datasets / "cmu/data/07/07_03.bvh").to_motion()[1:], canonical())
    session = RecurrentSession(input_fps=walk.fps, follow_seconds=2.0)
    outs = {size: stream(session, scaled(walk, size), "elderly") for size in (1.0, 0.8)}
    # The session measured the performer: 0.8 of what the full-size one gives.
    assert abs(session._scale.scale[0] / clip_scale(walk, session._scale.reference) - 0.8) < 0.03
    # Its output walks 0.8 times as far (the performer's own stride, not the canonical one) ...
    travel = {s: np.linalg.norm(o.root_positions[-1, [0, 2]] - o.root_positions[0, [0, 2]])
              for s, o in outs.items()}
    assert abs(travel[0.8] / travel[1.0] - 0.8) < 0.05, travel
    # ... and the stylized pose is the full-size performer's after the first second.
    g = {s: o.global_positions()[120:] - o.global_positions()[120:, o.skeleton.pelvis, None]
         for s, o in outs.items()}
    assert np.linalg.norm(g[0.8] - g[1.0], axis=-1).mean() < 0.03
