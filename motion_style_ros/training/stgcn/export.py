"""The ST-GCN generator and its two companions (mapping network, style encoder) as ONNX, with the
names of :mod:`motion_style_ros.runtime.contract`; their ONNX vs torch parity, the model card, and
untrained stand-ins with the real interface for runtime tests."""

from __future__ import annotations

from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np
import torch

from motion_style_ros.models.stgcn import Generator, MappingNetwork, StyleEncoder, tiny
from motion_style_ros.runtime.contract import MAPPING, STYLE_ENCODER, WINDOWED
from motion_style_ros.training import export
from motion_style_ros.training.data import NEUTRAL

# instance norm always normalises by the input's own statistics: "train=True" is right
_QUIET = ("ONNX export mode is set to TrainingMode.EVAL",)


def companions(path: Path) -> dict[str, Path]:
    """The mapping network and style encoder files beside the generator at ``path``."""
    return {"mapping": path.with_name(f"{path.stem}_mapping.onnx"),
            "style_encoder": path.with_name(f"{path.stem}_style_encoder.onnx")}


def export_onnx(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path) -> None:
    """The generator at ``path`` and its two companions (:func:`companions`), batch and time
    dynamic."""
    cfg = gen.cfg
    b, t = 2, cfg.window
    x = torch.zeros(b, t, cfg.n_features)
    files = companions(path)
    export.export_graph(gen, (x, torch.zeros(b, cfg.style_dim)), path, WINDOWED,
                        timed=("features", "output"), quiet=_QUIET)
    export.export_graph(mapping, (torch.zeros(b, cfg.latent_dim), torch.eye(len(cfg.styles))[[0] * b]),
                        files["mapping"], MAPPING, quiet=_QUIET)
    export.export_graph(encoder, (x,), files["style_encoder"], STYLE_ENCODER, timed=("features",),
                        quiet=_QUIET)


def parity(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path,
           clip: np.ndarray) -> float:
    """Largest ONNX vs torch difference of the three networks on ``clip`` ``(T, F)`` (cut into
    windows; every style's latent code)."""
    cfg = gen.cfg
    n = len(cfg.styles)
    t = len(clip) // cfg.window * cfg.window
    x = clip[:t].reshape(-1, cfg.window, clip.shape[-1]).astype(np.float32)
    z = np.random.default_rng(0).standard_normal((n, cfg.latent_dim)).astype(np.float32)
    style = np.eye(n, dtype=np.float32)
    files = companions(path)
    (codes,) = export.run_onnx(files["mapping"], MAPPING, z, style)
    xs = np.repeat(x, n, axis=0)
    cs = np.tile(codes, (len(x), 1))
    got = [codes, *export.run_onnx(path, WINDOWED, xs, cs),
           *export.run_onnx(files["style_encoder"], STYLE_ENCODER, x)]
    with torch.no_grad():
        expected = [mapping(torch.from_numpy(z), torch.from_numpy(style)).numpy(),
                    gen(torch.from_numpy(xs), torch.from_numpy(cs)).numpy(),
                    *(a.numpy() for a in encoder(torch.from_numpy(x)))]
    return float(max(np.abs(a - b).max() for a, b in zip(got, expected, strict=True)))


def card(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path, training: dict
         ) -> dict:
    """The model card of the generator at ``path`` and its companions."""
    cfg = gen.cfg
    n_styles = len(cfg.styles)

    def described(names: tuple[str, ...], *texts: str) -> dict[str, str]:
        return dict(zip(names, texts, strict=True))

    interface = {
        "window": cfg.window,
        "frames_multiple": 4,
        "style_dim": cfg.style_dim,
        "latent_dim": cfg.latent_dim,
        "opset": export.OPSET,
        "files": {k: p.name for k, p in companions(path).items()},
        "inputs": described(
            WINDOWED.inputs,
            f"(B, T, {cfg.n_features}) float32: motion_style_ros.core.features.encode() of T frames, raw "
            f"(normalised inside); T a multiple of 4, trained at {cfg.window}",
            f"(B, {cfg.style_dim}) float32 style code (mapping network or style encoder; codes may be "
            "interpolated)"),
        "outputs": described(
            WINDOWED.outputs,
            f"(B, T, {cfg.n_out}) float32: the stylized frames as encode()'s [root (4) | rot6d "
            f"({cfg.n_out - 4})] blocks, raw units, 6D rotations orthonormalised"),
        "mapping": {"inputs": described(MAPPING.inputs, f"(B, {cfg.latent_dim}) float32 standard normal noise",
                                        f"(B, {n_styles}) float32 one-hot over 'styles'"),
                    "outputs": described(MAPPING.outputs, f"(B, {cfg.style_dim}) float32")},
        "style_encoder": {
            "inputs": described(STYLE_ENCODER.inputs, f"(B, T, {cfg.n_features}) float32 raw, T >= "
                                                       f"{cfg.window} and a multiple of 4"),
            "outputs": described(STYLE_ENCODER.outputs,
                                 f"(B, {n_styles}, {cfg.style_dim}) float32: the clip's code under each "
                                 "style's head",
                                 f"(B, {n_styles}) float32: which style the clip is")},
    }
    architecture = {
        **{k: v for k, v in asdict(cfg).items() if k != "styles"},
        "parameters": {name: int(sum(p.numel() for p in m.parameters()))
                       for name, m in (("generator", gen), ("mapping", mapping), ("style_encoder", encoder))},
    }
    neutral = training.get("config", {}).get("neutral", NEUTRAL)  # the run's (--neutral), else normal
    return export.stylizer_card(
        path, "stgcn", "motion style transfer over windows of frames, streamed by overlap-add; style "
        "codes from a latent seed (mapping network) or a reference clip (style encoder)",
        cfg.styles, neutral if neutral in cfg.styles else cfg.styles[0], interface, architecture, training)


def write_model(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path,
                training: dict, probe: np.ndarray | None = None) -> dict:
    """The three ONNX graphs and the card beside the generator at ``path``; returns the card.
    With a ``probe`` clip ``(T, F)``, the card records the ONNX vs torch difference on it."""
    return export.write_model(path, partial(export_onnx, gen, mapping, encoder),
                              partial(parity, gen, mapping, encoder),
                              partial(card, gen, mapping, encoder, path), training, probe)


def export_random_model(path: Path, styles: list[str], seed: int = 0) -> None:
    """Untrained tiny networks with the real interface (identity normalisation), for runtime tests
    that must not depend on the shipped model. The generator's last layer is randomised so that
    its output depends on the code."""
    cfg = tiny(tuple(styles))
    torch.manual_seed(seed)
    mean, std = np.zeros(cfg.n_features), np.ones(cfg.n_features)
    gen = Generator(cfg, mean, std)
    with torch.no_grad():
        gen.last.weight.normal_(0.0, 0.05)
    write_model(gen, MappingNetwork(cfg), StyleEncoder(cfg, mean, std), Path(path),
                {"data": "none: random weights", "seed": seed})
