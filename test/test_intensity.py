"""Alpha is the style's intensity, through the shipped models on a real walk: 0 gives the performer
back exactly, values between fade in without jumps, and part alphas keep a body part as performed."""

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.intensity import PARTS, part_of_joints
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.runtime import offline
from motion_style_ros.runtime.backends import backend as spec

WALK = "dataset-2_walk_normal_010"


@pytest.fixture(scope="module")
def walk(datasets):
    path = datasets / f"bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/{WALK}.bvh"
    return load_clip(ClipInfo("bandai-2", path, WALK, "walk", "normal", "", ""))[:150]


def differences(a: Motion, b: Motion, joints=slice(None)) -> tuple[float, float]:
    """The largest local rotation angle (rad) and root distance (m) between two clips."""
    angle = rot.angle_between(a.rotations[:, joints], b.rotations[:, joints]).max()
    return float(angle), float(np.abs(a.root_positions - b.root_positions).max())


def joints_of(part: str) -> list[int]:
    return [j for j, k in enumerate(part_of_joints(canonical())) if PARTS[k] == part]


@pytest.mark.parametrize("fps", [30.0, 120.0])
@pytest.mark.parametrize("backend", ["recurrent", "stgcn", "most", "saae"])
def test_alpha_zero_gives_the_performer_back(walk, backend, fps):
    clip = resample(walk, fps)
    out = offline.stylizer(backend, alpha=0.0)(clip, "elderly")
    assert out.n_frames == clip.n_frames
    angle, distance = differences(out, clip)
    assert angle < 1e-6 and distance < 1e-6, (angle, distance)
    styled = offline.stylizer(backend)(clip, "elderly")
    assert differences(styled, clip)[0] > 0.1  # the full style is not the input


def test_alpha_ramped_in_while_streaming_never_jumps(walk):
    """0 to 1 over a second, at 120 Hz: no frame-to-frame joint step beyond 1.2 times the largest
    of the stream at alpha 1 (every joint's local rotation and the root)."""
    clip = resample(walk, 120.0)
    sessions = {}
    for name in ("ramp", "full"):
        sessions[name] = spec("recurrent").session_class()(spec("recurrent").default_model, input_fps=120.0,
                                                            blend_seconds=1.0)
        sessions[name].set_style("elderly")
    sessions["ramp"].set_alpha(0.0)
    outs = {name: [] for name in sessions}
    for k in range(clip.n_frames):
        if k == 30:  # a quarter second in, the fade starts
            sessions["ramp"].set_alpha(1.0)
        for name, session in sessions.items():
            outs[name].append(session.step(clip.rotations[k], clip.root_positions[k], k / clip.fps))

    def steps(frames):
        q = np.stack([f[0] for f in frames])
        p = np.stack([f[1] for f in frames])
        return rot.angle_between(q[1:], q[:-1]).max(axis=1), np.linalg.norm(np.diff(p, axis=0), axis=-1)

    ramp, full = steps(outs["ramp"]), steps(outs["full"])
    assert ramp[0].max() <= 1.2 * full[0].max(), (ramp[0].max(), full[0].max())
    assert ramp[1].max() <= 1.2 * full[1].max(), (ramp[1].max(), full[1].max())
    # before the fade: the input, the stream's latency later
    delay = round(sessions["ramp"].latency * clip.fps)
    first = np.stack([f[0] for f in outs["ramp"][delay:30]])
    assert rot.angle_between(first, clip.rotations[:30 - delay]).max() < 1e-6


@pytest.mark.parametrize("fps", [30.0, 120.0])
def test_legs_as_performed_arms_in_the_full_style(walk, fps):
    clip = resample(walk, fps)
    make = spec("recurrent").session_class()
    full, mixed = (make(spec("recurrent").default_model, input_fps=fps) for _ in range(2))
    mixed.set_part_alpha([1.0, 1.0, 0.0])
    styled, parted = (s.run(clip, "elderly") for s in (full, mixed))
    legs, arms = joints_of("legs"), joints_of("arms")
    angle, distance = differences(parted, clip, legs)
    assert angle < 1e-6 and distance < 1e-6, (angle, distance)
    assert differences(parted, styled, arms)[0] < 1e-6
    assert differences(styled, clip, arms)[0] > 0.1


def test_stylize_at_alpha_zero_writes_the_clip_back(datasets, tmp_path):
    """The command a user runs, on a CMU file (another rig, 120 Hz, its T-pose first): the BVH it
    writes at --alpha 0 is the input as the stylizers take it, every frame."""
    from motion_style_ros.cli.main import main
    from motion_style_ros.io.canonical import canonical_clip

    source = datasets / "cmu/data/02/02_01.bvh"
    out = tmp_path / "out.bvh"
    assert main(["stylize", str(source), "-o", str(out), "--style", "elderly", "--alpha", "0"]) == 0
    written, clip = canonical_clip(str(out)), canonical_clip(str(source))
    assert written.n_frames == clip.n_frames
    angle, distance = differences(written, clip)
    assert angle < 1e-6 and distance < 1e-6, (angle, distance)
