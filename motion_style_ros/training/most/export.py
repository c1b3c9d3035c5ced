"""MoST as ONNX with the names of :mod:`motion_style_ros.runtime.contract`: the streamed step
(content encoder, modulator, generator; :data:`~motion_style_ros.runtime.contract.MOST`), the style
side of the encoder run once per reference (:data:`~motion_style_ros.runtime.contract.MOST_STYLE`)
and every style's mean features (``target_style``); their ONNX vs torch parity, the model card,
and an untrained stand-in with the real interface for runtime tests."""

from __future__ import annotations

from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np
import torch

from motion_style_ros.models.most import (
    PARTS,
    MoST,
    Step,
    StyleFeatures,
    n_parameters,
    tiny,
)
from motion_style_ros.runtime.contract import MOST, MOST_STYLE
from motion_style_ros.training import export
from motion_style_ros.training.data import NEUTRAL


def companions(path: Path) -> dict[str, Path]:
    """The style encoder and the styles' mean features beside the step graph at ``path``."""
    return {"style_encoder": path.with_name(f"{path.stem}_style_encoder.onnx"),
            "style_means": path.with_name(f"{path.stem}_style_means.npz")}


def export_onnx(model: MoST, means: tuple[np.ndarray, np.ndarray], path: Path) -> None:
    """The step graph at ``path`` and its companions (:func:`companions`); batch and time dynamic.
    ``means``: every style's mean ``S`` and ``C`` ``(styles, P, D)``."""
    cfg = model.cfg
    b, p = 2, len(PARTS)
    x = torch.zeros(b, cfg.window, cfg.n_features)
    feat = torch.zeros(b, p, cfg.dim)
    files = companions(path)
    export.export_graph(Step(model), (x, feat, feat, torch.ones(b, 1)), path, MOST,
                        timed=("features", "output"))
    export.export_graph(StyleFeatures(model), (x,), files["style_encoder"], MOST_STYLE, timed=("features",))
    style, pooled = means
    np.savez(files["style_means"], style=style.astype(np.float32), pooled=pooled.astype(np.float32))


def parity(model: MoST, path: Path, clip: np.ndarray) -> float:
    """Largest ONNX vs torch difference of both graphs on ``clip`` ``(T, F)`` cut into windows,
    each window restyled like the clip's windows in reverse order at alphas from 0 to 1."""
    w = model.cfg.window
    t = len(clip) // w * w
    x = clip[:t].reshape(-1, w, clip.shape[-1]).astype(np.float32)
    alpha = np.linspace(0.0, 1.0, len(x), dtype=np.float32)[:, None]
    style, pooled = export.run_onnx(companions(path)["style_encoder"], MOST_STYLE, x)
    ref = style[::-1].copy(), pooled[::-1].copy()
    (out,) = export.run_onnx(path, MOST, x, *ref, alpha)
    with torch.no_grad():
        expected = [*(a.numpy() for a in StyleFeatures(model)(torch.from_numpy(x))),
                    Step(model)(torch.from_numpy(x), *map(torch.from_numpy, ref), torch.from_numpy(alpha)).numpy()]
    return float(max(np.abs(a - b).max() for a, b in zip([style, pooled, out], expected, strict=True)))


def card(model: MoST, path: Path, training: dict) -> dict:
    """The model card of the step graph at ``path`` and its companions."""
    cfg = model.cfg
    p, d = len(PARTS), cfg.dim

    def described(names: tuple[str, ...], *texts: str) -> dict[str, str]:
        return dict(zip(names, texts, strict=True))

    interface = {
        "window": cfg.window,
        "parts": [part.name for part in PARTS],
        "feature_dim": d,
        "opset": export.OPSET,
        "files": {k: q.name for k, q in companions(path).items()},
        "inputs": described(
            MOST.inputs,
            f"(B, T, {cfg.n_features}) float32: motion_style_ros.core.features.encode() of T frames, raw "
            f"(normalised inside); trained at T = {cfg.window}",
            f"(B, {p}, {d}) float32: the style motion's body-part style feature S (style encoder, or a "
            "style's mean from style_means)",
            f"(B, {p}, {d}) float32: the style motion's content feature C averaged over its frames",
            "(B, 1) float32 alpha: 0 restyles the window like itself (reconstruction), 1 like the style motion"),
        "outputs": described(
            MOST.outputs,
            f"(B, T, {cfg.n_out}) float32: the stylized frames as encode()'s [root (4) | rot6d "
            f"({cfg.n_out - 4})] blocks, raw units, 6D rotations orthonormalised"),
        "style_encoder": {
            "inputs": described(MOST_STYLE.inputs, f"(B, T, {cfg.n_features}) float32 raw, T = {cfg.window} "
                                                    "(a longer clip: its windows' features averaged)"),
            "outputs": described(MOST_STYLE.outputs, f"(B, {p}, {d}) float32 S", f"(B, {p}, {d}) float32 C")},
        "style_means": f"npz: 'style' and 'pooled', ({len(cfg.styles)}, {p}, {d}) float32 each, in "
                       "the order of 'styles'",
    }
    architecture = {
        **{k: v for k, v in asdict(cfg).items() if k != "styles"},
        "parameters": {name: n_parameters(m) for name, m in (
            ("encoder", model.encoder), ("modulator", model.modulator), ("generator", model.generator))},
    }
    neutral = training.get("config", {}).get("neutral", NEUTRAL)
    return export.stylizer_card(
        path, "most", "motion style transfer from a reference motion of any action (MoST) over windows "
        "of frames, streamed by overlap-add; the reference's features computed once, or a style's mean",
        cfg.styles, neutral if neutral in cfg.styles else cfg.styles[0], interface, architecture, training)


def write_model(model: MoST, path: Path, training: dict, probe: np.ndarray | None,
                means: tuple[np.ndarray, np.ndarray]) -> dict:
    """Both graphs, the styles' mean features and the card beside the step graph at ``path``;
    returns the card. With a ``probe`` clip ``(T, F)``, the card records the ONNX vs torch
    difference on it."""
    model = model.eval()
    return export.write_model(path, partial(export_onnx, model, means), partial(parity, model),
                              partial(card, model, path), training, probe)


def export_random_model(path: Path, styles: list[str], seed: int = 0) -> dict:
    """Untrained tiny networks with the real interface (identity normalisation), for runtime tests
    that must not depend on a trained model; each style's mean features from random windows of its
    own, so that styles differ."""
    cfg = tiny(tuple(styles))
    torch.manual_seed(seed)
    model = MoST(cfg, np.zeros(cfg.n_features), np.ones(cfg.n_features)).eval()
    with torch.no_grad():
        got = [StyleFeatures(model)(torch.randn(4, cfg.window, cfg.n_features)) for _ in styles]
    means = (np.stack([s.mean(0).numpy() for s, _ in got]), np.stack([c.mean(0).numpy() for _, c in got]))
    return write_model(model, Path(path), {"data": "none: random weights", "seed": seed}, None, means)
