"""The SAAE's networks as ONNX under the names of :mod:`motion_style_ros.runtime.contract` (the
decoder is the model file, the encoder and Model2's style encoder its companions), their ONNX vs
torch parity, the model card, and untrained stand-ins with the real interface for runtime tests."""

from __future__ import annotations

from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np
import torch

from motion_style_ros.models.saae import (
    ContentGraph,
    Critic,
    Decoder,
    Encoder,
    SaaeConfig,
    StyleGraph,
    positions,
    tiny,
)
from motion_style_ros.runtime.contract import (
    SAAE_DECODER,
    SAAE_ENCODER,
    SAAE_STYLE_ENCODER,
)
from motion_style_ros.training import export
from motion_style_ros.training.data import NEUTRAL

_QUIET = ("Exporting a model to ONNX with a batch_size other than 1",)


def model_name(variant: str, style_dim: int) -> str:
    """The model file's stem: ``saae_plain``, ``saae_model1``, ``saae_model2_<d>d`` (the paper's
    three models and Model2's style sizes side by side in one folder)."""
    return {"saae": "saae_plain", "model1": "saae_model1"}.get(variant, f"saae_model2_{style_dim}d")


def companions(path: Path, variant: str) -> dict[str, Path]:
    """The encoder (and Model2's style encoder) beside the decoder at ``path``."""
    files = {"encoder": path.with_name(f"{path.stem}_encoder.onnx")}
    if variant == "model2":
        files["style_encoder"] = path.with_name(f"{path.stem}_style_encoder.onnx")
    return files


def export_onnx(enc: Encoder, dec: Decoder, classifier: Critic | None, path: Path) -> None:
    """The decoder at ``path``, its companions (:func:`companions`) beside it; batch and time
    dynamic."""
    cfg = dec.cfg
    b, t = 2, cfg.window
    files = companions(path, cfg.variant)
    x = torch.zeros(b, t, cfg.n_features)
    export.export_graph(dec, (torch.zeros(b, cfg.content_dim), torch.zeros(b, cfg.style_width),
                              positions(t, cfg.window, b).contiguous()),
                        path, SAAE_DECODER, timed=("position", "output"), quiet=_QUIET)
    export.export_graph(ContentGraph(enc), (x,), files["encoder"], SAAE_ENCODER, timed=("features",),
                        quiet=_QUIET)
    if cfg.variant == "model2":
        export.export_graph(StyleGraph(enc, classifier), (x,), files["style_encoder"], SAAE_STYLE_ENCODER,
                            timed=("features",), quiet=_QUIET)


def parity(enc: Encoder, dec: Decoder, classifier: Critic | None, path: Path, clip: np.ndarray) -> float:
    """Largest ONNX vs torch difference of the graphs on ``clip`` ``(T, F)`` cut into windows
    (decoded from their own codes, and from random codes and style inputs)."""
    cfg = dec.cfg
    t = max(len(clip) // cfg.window, 1) * cfg.window
    x = clip[:t].reshape(-1, cfg.window, clip.shape[-1]).astype(np.float32)
    rng = np.random.default_rng(0)
    z = rng.standard_normal((len(x), cfg.content_dim)).astype(np.float32)
    style = rng.standard_normal((len(x), cfg.style_width)).astype(np.float32)
    pos = positions(cfg.window, cfg.window, len(x)).numpy().copy()
    files = companions(path, cfg.variant)
    got = [*export.run_onnx(files["encoder"], SAAE_ENCODER, x),
           *export.run_onnx(path, SAAE_DECODER, z, style, pos)]
    with torch.no_grad():
        content, code = enc(torch.from_numpy(x))
        expected = [content.numpy(), dec(torch.from_numpy(z), torch.from_numpy(style), torch.from_numpy(pos)).numpy()]
        if cfg.variant == "model2":
            got += export.run_onnx(files["style_encoder"], SAAE_STYLE_ENCODER, x)
            expected += [code.numpy(), classifier(code).numpy()]
    return float(max(np.abs(a - b).max() for a, b in zip(got, expected, strict=True)))


def card(enc: Encoder, dec: Decoder, classifier: Critic | None, path: Path, style_inputs: np.ndarray,
         style_spread: np.ndarray, training: dict) -> dict:
    """The model card of the decoder at ``path``: with each style's decoder style input
    (``style_inputs`` ``(S, style_width)``: one-hot, Model2's mean style code, or 0) and its spread
    (``style_spread``, Model2's per-style std of the style code; 0 otherwise)."""
    cfg = dec.cfg
    n = len(cfg.styles)

    def described(names: tuple[str, ...], *texts: str) -> dict[str, str]:
        return dict(zip(names, texts, strict=True))

    style_text = {"model1": f"one-hot over 'styles' ({n})", "model2": f"the {cfg.style_dim}-dim style code "
                  "(style encoder on a clip, or 'style_inputs' per style)", "saae": "one 0 (no style input)"}
    interface = {
        "window": cfg.window,
        "frames_multiple": 1,
        "variant": cfg.variant,
        "content_dim": cfg.content_dim,
        "style_width": cfg.style_width,
        "style_dim": cfg.style_dim if cfg.variant == "model2" else 0,
        "prior": f"content codes ~ N(0, I) in {cfg.content_dim} dims",
        "opset": export.OPSET,
        "files": {k: p.name for k, p in companions(path, cfg.variant).items()},
        "style_inputs": {s: [round(float(v), 6) for v in row] for s, row in zip(cfg.styles, style_inputs)},
        "style_spread": {s: [round(float(v), 6) for v in row] for s, row in zip(cfg.styles, style_spread)},
        "inputs": described(
            SAAE_DECODER.inputs, f"(B, {cfg.content_dim}) float32 content code (encoder, or N(0, I) samples)",
            f"(B, {cfg.style_width}) float32: {style_text[cfg.variant]}",
            f"(B, T) float32: each frame's index / {cfg.window} (trained on T = {cfg.window})"),
        "outputs": described(
            SAAE_DECODER.outputs, f"(B, T, {cfg.n_out}) float32: encode()'s [root (4) | rot6d "
            f"({cfg.n_out - 4})] blocks, raw units, 6D rotations orthonormalised"),
        "encoder": {"inputs": described(SAAE_ENCODER.inputs, f"(B, T, {cfg.n_features}) float32 raw "
                                                               f"encode() features, trained at T = {cfg.window}"),
                    "outputs": described(SAAE_ENCODER.outputs, f"(B, {cfg.content_dim}) float32")},
    }
    if cfg.variant == "model2":
        interface["style_encoder"] = {
            "inputs": described(SAAE_STYLE_ENCODER.inputs, f"(B, T, {cfg.n_features}) float32 raw"),
            "outputs": described(SAAE_STYLE_ENCODER.outputs, f"(B, {cfg.style_dim}) float32 style code",
                                 f"(B, {n}) float32: which style the window is (the style code's classifier)")}
    nets = [("encoder", enc), ("decoder", dec)] + ([("style_classifier", classifier)] if classifier else [])
    architecture = {**{k: v for k, v in asdict(cfg).items() if k != "styles"},
                    "parameters": {name: int(sum(p.numel() for p in m.parameters())) for name, m in nets}}
    neutral = training.get("config", {}).get("neutral", NEUTRAL)
    task = {"model1": "restyling windows by a style label (Model1)",
            "model2": "restyling windows by a style code, of a style label or a reference clip (Model2)",
            "saae": "the plain SAAE baseline: reconstruction and unconditioned generation (no restyling)"}
    return export.stylizer_card(
        path, "saae", f"sequence adversarial autoencoder (ESANN 2018): {task[cfg.variant]}; the decoder "
        "alone generates windows from prior samples", cfg.styles, neutral if neutral in cfg.styles else cfg.styles[0],
        interface, architecture, training)


def write_model(enc: Encoder, dec: Decoder, classifier: Critic | None, path: Path, style_inputs: np.ndarray,
                style_spread: np.ndarray, training: dict, probe: np.ndarray | None = None) -> dict:
    """The ONNX graphs and the card beside the decoder at ``path``; returns the card."""
    return export.write_model(path, partial(export_onnx, enc, dec, classifier),
                              partial(parity, enc, dec, classifier),
                              partial(card, enc, dec, classifier, path, style_inputs, style_spread),
                              training, probe)


def export_random_model(path: Path, styles: list[str], variant: str = "model2", seed: int = 0) -> dict:
    """Untrained tiny networks with the real interface (identity normalisation), for runtime tests
    that must not depend on a trained model; returns the card."""
    cfg = tiny(tuple(styles), variant)
    torch.manual_seed(seed)
    mean, std = np.zeros(cfg.n_features), np.ones(cfg.n_features)
    enc, dec = Encoder(cfg, mean, std), Decoder(cfg, mean, std)
    classifier = Critic(cfg.style_dim, cfg.critic_hidden, len(styles)) if variant == "model2" else None
    inputs, spread = random_style_inputs(cfg, seed)
    return write_model(enc, dec, classifier, Path(path), inputs, spread,
                       {"data": "none: random weights", "seed": seed})


def random_style_inputs(cfg: SaaeConfig, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per-style style inputs and spreads for an untrained model: one-hot (Model1), random codes
    (Model2), 0 (plain)."""
    n = len(cfg.styles)
    if cfg.variant == "model1":
        return np.eye(n), np.zeros((n, n))
    if cfg.variant == "model2":
        return np.random.default_rng(seed).standard_normal((n, cfg.style_dim)), np.full((n, cfg.style_dim), 0.1)
    return np.zeros((n, 1)), np.zeros((n, 1))
