"""The Style-ERD streaming step as ONNX (recurrent state as explicit input and output, names from
:data:`motion_style_ros.runtime.contract.RECURRENT`), its ONNX vs torch parity, its model card, and
an untrained stand-in with the real interface for runtime tests."""

from __future__ import annotations

from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np
import torch

from motion_style_ros.models.style_erd import ErdConfig, StepGraph, StyleERD, tiny
from motion_style_ros.runtime.contract import RECURRENT
from motion_style_ros.training import export


def export_onnx(model: StyleERD, path: Path) -> None:
    """The streaming step as ONNX: one frame and the recurrent state in, the stylized frame and the
    next state out; batch dynamic."""
    cfg = model.cfg
    b = 2
    example = (
        torch.zeros(b, cfg.n_features),
        torch.eye(len(cfg.styles))[[0] * b],
        torch.ones(b, 1),
        torch.zeros(b, cfg.state_size),
        torch.ones(b, 1),
    )
    export.export_graph(StepGraph(model), example, path, RECURRENT,
                        quiet=("Exporting a model to ONNX with a batch_size",))


def parity(model: StyleERD, onnx_path: Path, features: np.ndarray) -> float:
    """Largest difference between the ONNX graph stepped frame by frame (state carried) and the
    torch model run over the whole ``(T, F)`` clip, for each style as the target."""
    n = len(model.cfg.styles)
    style = np.eye(n, dtype=np.float32)
    alpha = np.ones((n, 1), np.float32)
    x = np.repeat(features[None].astype(np.float32), n, axis=0)
    with torch.no_grad():
        expected, _ = model.eval()(torch.from_numpy(x), torch.from_numpy(style), torch.from_numpy(alpha))
    state = np.zeros((n, model.cfg.state_size), np.float32)
    worst = 0.0
    for t in range(len(features)):
        reset = np.full((n, 1), float(t == 0), np.float32)
        out, state = export.run_onnx(onnx_path, RECURRENT, x[:, t], style, alpha, state, reset)
        worst = max(worst, float(np.abs(out - expected[:, t].numpy()).max()))
    return worst


def card(model: StyleERD, path: Path, training: dict) -> dict:
    """The model card of the graph at ``path``."""
    cfg = model.cfg
    n_out = cfg.n_out
    inputs = (
        f"(B, {cfg.n_features}) float32: motion_style_ros.core.features.encode() of the current input "
        "frame, raw (normalised inside the graph)",
        f"(B, {len(cfg.styles)}) float32 weights over 'styles' (one-hot or a mix, rows sum to 1); every "
        "branch runs at every step, the weights only mix outputs",
        "(B, 1) float32 in [0, 1]: scales the style residual and the decoder's style conditioning; "
        f"0 = the neutral branch alone (same as style '{cfg.neutral}')",
        f"(B, {cfg.state_size}) float32: every LSTM h and c, flattened (ignored where reset=1)",
        "(B, 1) float32: where 1, the learned initial state replaces 'state' before the step (first "
        "frame, after reset or a gap); it does not depend on 'style' since every branch has its own",
    )
    outputs = (
        f"(B, {n_out}) float32: the stylized frame as encode()'s [root (4) | rot6d ({n_out - 4})] "
        "blocks, raw units, 6D rotations orthonormalised",
        f"(B, {cfg.state_size}) float32: the state to pass at the next frame",
    )
    interface = {
        "state_size": cfg.state_size,
        "opset": export.OPSET,
        "inputs": dict(zip(RECURRENT.inputs, inputs, strict=True)),
        "outputs": dict(zip(RECURRENT.outputs, outputs, strict=True)),
    }
    architecture = {
        **{k: v for k, v in asdict(cfg).items() if k != "styles"},
        "branch_styles": list(cfg.branch_styles),
        "parameters": int(sum(p.numel() for p in model.parameters())),
    }
    return export.stylizer_card(
        path, "recurrent", "online motion style transfer: one frame in, one stylized frame out, no lookahead",
        cfg.styles, cfg.neutral, interface, architecture, training)


def write_model(model: StyleERD, path: Path, training: dict, probe: np.ndarray | None = None) -> dict:
    """ONNX graph at ``path`` and its card beside it; returns the card. With a ``probe`` clip
    ``(T, F)``, the card records the ONNX vs torch difference on it (:func:`parity`)."""
    return export.write_model(path, partial(export_onnx, model), partial(parity, model),
                              partial(card, model, path), training, probe)


def export_random_model(path: Path, styles: list[str], seed: int = 0, neutral: str = "normal") -> None:
    """An untrained tiny generator with the real interface (identity normalisation), for runtime
    tests that must not depend on the shipped model."""
    cfg: ErdConfig = tiny(tuple(styles), neutral)
    torch.manual_seed(seed)
    model = StyleERD(cfg, np.zeros(cfg.n_features), np.ones(cfg.n_features),
                     np.zeros(cfg.n_out), np.ones(cfg.n_out))
    with torch.no_grad():  # make the learned initial state non-trivial, as a trained one is
        for p in model.initial:
            p.normal_(0.0, 0.3)
    write_model(model, Path(path), {"data": "none: random weights", "seed": seed})
