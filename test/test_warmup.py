"""The warm-up compiles every kernel a stream and the clip functions use, each with one signature:
a stream of any backend, live conditioning on a real rig, then compiles nothing more."""

import importlib
import pkgutil

import numpy as np
from numba.core.registry import CPUDispatcher

import motion_style_ros.core
import motion_style_ros.io
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.features import decode, encode
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.runtime.offline import stylizer
from motion_style_ros.runtime.recurrent import RecurrentSession
from motion_style_ros.runtime.warmup import warm_kernels


def signatures() -> dict[str, int]:
    """Every compiled kernel of the package (wherever it lives) with its number of signatures."""
    found = {}
    for package in (motion_style_ros.core, motion_style_ros.io):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            module = importlib.import_module(info.name)
            for name, f in vars(module).items():
                if isinstance(f, CPUDispatcher) and f.py_func.__module__ == info.name:
                    found[f"{info.name}.{name}"] = len(f.signatures)
    return found


def test_after_the_warm_up_no_stream_or_clip_compiles_a_kernel():
    assert warm_kernels() >= 0.0
    warmed = signatures()
    assert all(n <= 1 for n in warmed.values()), warmed  # one signature each
    walk = synthetic_motion("walk", 60.0, 2.0)
    wave = synthetic_motion("wave", 120.0, 2.0)
    # a rig of its own: arms rolled and a taller performer, measured live, two performers
    session = RecurrentSession("style_erd.onnx", 2, input_fps=wave.fps)
    rolled = wave.rotations.copy()
    rolled[:, 7:9] = rot.multiply(rolled[:, 7:9], rot.from_axis_angle(np.array([1.0, 0.0, 0.0]), 0.4))
    for k in range(wave.n_frames):
        session.step(np.stack([wave.rotations[k], rolled[k]]).astype(np.float32),
                     np.stack([wave.root_positions[k], 1.2 * wave.root_positions[k]]), k / wave.fps)
    for backend in ("recurrent", "stgcn", "most", "saae"):
        assert np.isfinite(stylizer(backend)(walk, "elderly").rotations).all()
    decode(encode(walk[:10]), walk.fps)
    assert signatures() == warmed
