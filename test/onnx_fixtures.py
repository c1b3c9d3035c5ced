"""Small random ONNX stylizers built with onnx's helper API, so that the torch-free runtime's tests
need no torch (``pip install .`` plus the test requirements runs them).

The graphs are not the real architectures, only their contracts
(:mod:`motion_style_ros.runtime.contract`: names, dtypes, dynamic axes) and cards the sessions
accept. Their outputs are plausible motion, so foot locking, grounding and decoding see sane
frames: the input's ``[root | rot6d]`` blocks plus small tanh-bounded residuals that depend on
every input (features, style, alpha, state and reset; the window and the code), so a test of any
control can fail. Like a trained model, the recurrent one walks slower than its input and pulls
the pelvis towards the training data's height (it does not simply pass the input's trajectory on).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from motion_style_ros.core.features import FEATURE_VERSION, feature_layout
from motion_style_ros.runtime.contract import MAPPING, RECURRENT, STYLE_ENCODER, WINDOWED, Contract

OPSET = 17  # as the exporters in training/
FPS = 30.0
LAYOUT = feature_layout()
N_FEATURES = LAYOUT.size
N_OUT = LAYOUT.slices["rot6d"].stop  # [root | rot6d]
PELVIS_HEIGHT = 0.9  # m: the Bandai takes' mean standing pelvis height
RANDOM = "none: random weights (test/onnx_fixtures.py)"  # bench's note keys on "random"


def recurrent_model(path: str | Path, styles: Sequence[str], seed: int = 0, neutral: str = "normal",
                    state_size: int = 32) -> Path:
    """A Style-ERD stand-in at ``path`` (card beside it). Per frame, with ``s`` the state (the
    learned initial one where ``reset`` is 1):

    ``state_out = 0.7 s + 0.3 tanh(features A + s R)``;
    ``output = base(features) + 0.05 tanh(state_out N) + 0.25 alpha sum_k style_k tanh(state_out S_k + P_k)``

    where ``base`` is the input frame with the root's speed halved and its height pulled halfway
    to :data:`PELVIS_HEIGHT`, ``P_k`` is style k's own pose (the root's residuals are 0.05 at
    most), and the neutral style's branch is zero: alpha 0 and the neutral style give the same
    frame, as in the real model."""
    styles = list(styles)
    rng = np.random.default_rng(seed)
    n_styles, n = len(styles), state_size
    branches = rng.normal(0.0, 1.0 / np.sqrt(n), (n, n_styles, N_OUT))
    poses = rng.normal(0.0, 1.0, (n_styles, N_OUT))  # each style's own pose
    branches[:, styles.index(neutral)] = poses[styles.index(neutral)] = 0.0
    gain, offset = np.ones(N_OUT), np.zeros(N_OUT)
    gain[:3] = 0.5  # vx, vz, height (the root block: vx, vz, height, yaw rate)
    offset[2] = 0.5 * PELVIS_HEIGHT
    scale = np.full(N_OUT, 0.05)
    style_scale = np.full(N_OUT, 0.25)
    scale[:4] = style_scale[:4] = 0.05
    weights = {
        "init": rng.normal(0.0, 0.3, (1, n)),
        "A": rng.normal(0.0, 1.0 / np.sqrt(N_FEATURES), (N_FEATURES, n)),
        "R": rng.normal(0.0, 0.5 / np.sqrt(n), (n, n)),
        "N": rng.normal(0.0, 1.0 / np.sqrt(n), (n, N_OUT)),
        "S": branches.reshape(n, n_styles * N_OUT),
        "pose": poses.reshape(1, n_styles * N_OUT),
        "branch_shape": np.array([-1, n_styles, N_OUT], dtype=np.int64),
        "gain": gain, "offset": offset, "scale": scale, "style_scale": style_scale,
        "keep": np.float32(0.7), "take": np.float32(0.3), "half": np.float32(0.5),
        **_slice_constants(),
    }
    nodes = [
        helper.make_node("Greater", ["reset", "half"], ["fresh"]),
        helper.make_node("Where", ["fresh", "init", "state"], ["s"]),
        *_matmul_add_tanh("features", "A", "s", "R", "drive"),
        helper.make_node("Mul", ["s", "keep"], ["kept"]),
        helper.make_node("Mul", ["drive", "take"], ["taken"]),
        helper.make_node("Add", ["kept", "taken"], ["state_out"]),
        _base("features", "frame"),
        helper.make_node("Mul", ["frame", "gain"], ["slowed"]),
        helper.make_node("Add", ["slowed", "offset"], ["base"]),
        helper.make_node("MatMul", ["state_out", "N"], ["neutral_in"]),
        helper.make_node("Tanh", ["neutral_in"], ["neutral"]),
        helper.make_node("MatMul", ["state_out", "S"], ["branches_moved"]),
        helper.make_node("Add", ["branches_moved", "pose"], ["branches_in"]),
        helper.make_node("Tanh", ["branches_in"], ["branches_flat"]),
        helper.make_node("Reshape", ["branches_flat", "branch_shape"], ["branches"]),
        helper.make_node("Unsqueeze", ["style", "axis1"], ["style_row"]),
        helper.make_node("MatMul", ["style_row", "branches"], ["mixed_row"]),
        helper.make_node("Squeeze", ["mixed_row", "axis1"], ["mixed"]),
        helper.make_node("Mul", ["mixed", "alpha"], ["styled"]),
        helper.make_node("Mul", ["styled", "style_scale"], ["styled_scaled"]),
        helper.make_node("Mul", ["neutral", "scale"], ["neutral_scaled"]),
        helper.make_node("Add", ["neutral_scaled", "styled_scaled"], ["scaled"]),
        helper.make_node("Add", ["base", "scaled"], ["output"]),
    ]
    shapes = {"features": ["batch", N_FEATURES], "style": ["batch", n_styles], "alpha": ["batch", 1],
              "state": ["batch", n], "reset": ["batch", 1], "output": ["batch", N_OUT],
              "state_out": ["batch", n]}
    path = Path(path)
    _save(path, nodes, weights, RECURRENT, shapes)
    _write_card(path, "recurrent", styles, seed, neutral_style=neutral, state_size=n)
    return path


def windowed_model(path: str | Path, styles: Sequence[str], seed: int = 0, residual: float = 0.1,
                   window: int = 32, style_dim: int = 8, latent_dim: int = 16) -> Path:
    """An ST-GCN stand-in at ``path`` with its mapping network and style encoder beside it (the
    card names them). The generator returns each frame's ``[root | rot6d]`` blocks plus
    ``residual * tanh(features_t F + mean_t(features) M + code C)``: a frame's output depends on
    its window and the code; ``residual=0`` is the identity. The mapping network is
    ``tanh(z Z + style Y)``, the style encoder reads the window's mean features."""
    styles = list(styles)
    rng = np.random.default_rng(seed)
    n_styles, hidden = len(styles), 16
    path = Path(path)
    files = {"mapping": f"{path.stem}_mapping.onnx", "style_encoder": f"{path.stem}_style_encoder.onnx"}
    frames = ["batch", "frames", N_FEATURES]

    def drawn(rows: int, cols: int, gain: float = 1.0) -> np.ndarray:
        return rng.normal(0.0, gain / np.sqrt(rows), (rows, cols))

    generator = {"F": drawn(N_FEATURES, hidden), "M": drawn(N_FEATURES, hidden),
                 "C": drawn(style_dim, hidden), "U": drawn(hidden, N_OUT), "residual": np.float32(residual),
                 **_slice_constants()}
    _save(path, [
        helper.make_node("ReduceMean", ["features"], ["window_mean"], axes=[1], keepdims=1),
        helper.make_node("MatMul", ["features", "F"], ["per_frame"]),
        helper.make_node("MatMul", ["window_mean", "M"], ["per_window"]),
        helper.make_node("MatMul", ["code", "C"], ["coded"]),
        helper.make_node("Unsqueeze", ["coded", "axis1"], ["per_code"]),
        helper.make_node("Add", ["per_frame", "per_window"], ["framed"]),
        helper.make_node("Add", ["framed", "per_code"], ["hidden_in"]),
        helper.make_node("Tanh", ["hidden_in"], ["hidden"]),
        helper.make_node("MatMul", ["hidden", "U"], ["change_in"]),
        helper.make_node("Tanh", ["change_in"], ["change"]),
        helper.make_node("Mul", ["change", "residual"], ["scaled"]),
        _base("features", "frame"),
        helper.make_node("Add", ["frame", "scaled"], ["output"]),
    ], generator, WINDOWED, {"features": frames, "code": ["batch", style_dim],
                             "output": ["batch", "frames", N_OUT]})
    mapping = {"Z": drawn(latent_dim, style_dim, 2.0), "Y": drawn(n_styles, style_dim, 2.0)}
    _save(path.with_name(files["mapping"]), [
        *_matmul_add_tanh("z", "Z", "style", "Y", "code"),
    ], mapping, MAPPING, {"z": ["batch", latent_dim], "style": ["batch", n_styles],
                          "code": ["batch", style_dim]})
    encoder = {"E": drawn(N_FEATURES, n_styles * style_dim), "L": drawn(N_FEATURES, n_styles),
               "code_shape": np.array([-1, n_styles, style_dim], dtype=np.int64)}
    _save(path.with_name(files["style_encoder"]), [
        helper.make_node("ReduceMean", ["features"], ["clip_mean"], axes=[1], keepdims=0),
        helper.make_node("MatMul", ["clip_mean", "E"], ["codes_in"]),
        helper.make_node("Tanh", ["codes_in"], ["codes_flat"]),
        helper.make_node("Reshape", ["codes_flat", "code_shape"], ["codes"]),
        helper.make_node("MatMul", ["clip_mean", "L"], ["logits"]),
    ], encoder, STYLE_ENCODER, {"features": frames, "codes": ["batch", n_styles, style_dim],
                                "logits": ["batch", n_styles]})
    neutral = "normal" if "normal" in styles else styles[0]
    _write_card(path, "stgcn", styles, seed, neutral_style=neutral, window=window, frames_multiple=4,
                style_dim=style_dim, latent_dim=latent_dim, files=files)
    return path


def _slice_constants() -> dict[str, np.ndarray]:
    """What :func:`_base` and the unsqueezes read: the output's feature columns, axis 1."""
    return {"first": np.array([0], dtype=np.int64), "out_end": np.array([N_OUT], dtype=np.int64),
            "last_axis": np.array([-1], dtype=np.int64), "axis1": np.array([1], dtype=np.int64)}


def _base(features: str, out: str) -> onnx.NodeProto:
    """The input's ``[root | rot6d]`` columns (the leading ``N_OUT`` features), any leading axes."""
    return helper.make_node("Slice", [features, "first", "out_end", "last_axis"], [out])


def _matmul_add_tanh(a: str, wa: str, b: str, wb: str, out: str) -> list[onnx.NodeProto]:
    """``tanh(a wa + b wb)``."""
    return [helper.make_node("MatMul", [a, wa], [f"{out}_a"]),
            helper.make_node("MatMul", [b, wb], [f"{out}_b"]),
            helper.make_node("Add", [f"{out}_a", f"{out}_b"], [f"{out}_in"]),
            helper.make_node("Tanh", [f"{out}_in"], [out])]


def _save(path: Path, nodes: list[onnx.NodeProto], weights: dict[str, np.ndarray], contract: Contract,
          shapes: dict[str, list]) -> None:
    """The graph with float32 (int64 kept) initialisers and the contract's inputs and outputs in
    order, checked by onnx before it is written."""
    arrays = {name: np.asarray(v) for name, v in weights.items()}
    inits = [numpy_helper.from_array(a if a.dtype == np.int64 else a.astype(np.float32), name)
             for name, a in arrays.items()]
    io = {name: helper.make_tensor_value_info(name, TensorProto.FLOAT, shapes[name])
          for name in (*contract.inputs, *contract.outputs)}
    graph = helper.make_graph(nodes, path.stem, [io[n] for n in contract.inputs],
                              [io[n] for n in contract.outputs], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 8  # what the exporters write for opset 17
    onnx.checker.check_model(model, full_check=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))


def _write_card(path: Path, kind: str, styles: list[str], seed: int, **keys) -> None:
    """The card beside ``path``, with the keys every stylizer's card has."""
    card = {"name": path.stem, "kind": kind, "styles": styles, **keys, "fps": FPS, "skeleton": "canonical",
            "feature_version": FEATURE_VERSION,
            "feature_layout": {k: [s.start, s.stop] for k, s in LAYOUT.slices.items()},
            "opset": OPSET, "training": {"data": RANDOM, "seed": seed}, "metrics": {}}
    path.with_suffix(".json").write_text(json.dumps(card, indent=2) + "\n")
