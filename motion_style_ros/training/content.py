"""The content network: a content classifier trained on the train takes' content labels before a
stylizer's run, then frozen, whose features (Style-ERD's perceptual loss) or verdict (MoST's
content-classifier term) tell a trainer whether a transfer still does what its input did. It is
trained here, on train takes only; the evaluation judges in ``models/`` are never used."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from motion_style_ros.core.features import feature_layout
from motion_style_ros.models.style_erd import ContentNet
from motion_style_ros.training.data import Data, DataConfig, windows
from motion_style_ros.training.loop import PROGRESS_INTERVAL
from motion_style_ros.training.losses import Losses


@dataclass(frozen=True)
class ContentConfig(DataConfig):
    """The data fields, then the content network's; a stylizer's config that trains one starts so."""

    content_widths: tuple[int, ...] = (128, 96, 64)
    content_iterations: int = 1500
    content_batch: int = 32
    content_lr: float = 1e-3


def _settings(cfg: ContentConfig) -> dict:
    """What a saved content network must have been trained with to be loaded again."""
    names = ("seed", "datasets", "data", "std_floor", "content_widths", "content_iterations",
             "content_batch", "content_lr")
    return {"window": cfg.window, **{k: getattr(cfg, k) for k in names}}


FRAME = feature_layout().slices["rot6d"].stop  # encode()'s [root | rot6d] blocks lead its layout


def frames(x: torch.Tensor) -> torch.Tensor:
    """The ``[root | rot6d]`` part of encode() features: what the generators output."""
    return x[..., :FRAME]


def content_network(cfg: ContentConfig, data: Data, losses: Losses, path: Path, progress: bool = True,
                    device: torch.device | None = None) -> tuple[ContentNet, dict]:
    """The frozen content network: loaded from ``path``, or trained on the train takes' content
    labels (windows of ``cfg.window`` frames) and saved there. Returns it and its val window
    accuracy."""
    channels = losses.rot_cols.stop - losses.rot_cols.start + losses.pv_cols.stop - losses.pv_cols.start
    torch.manual_seed(cfg.seed)
    device = device or torch.device("cpu")
    net = ContentNet(channels, len(data.contents), cfg.content_widths).to(device)
    if path.exists():
        saved = torch.load(path, map_location="cpu", weights_only=False)
        if saved["settings"] == _settings(cfg) and saved["contents"] == list(data.contents):
            net.load_state_dict(saved["model"])
            return net.requires_grad_(False).eval(), saved["info"]
    optimizer = torch.optim.Adam(net.parameters(), lr=cfg.content_lr)
    # one content (a folder labelled by style only) leaves nothing to learn: its random features stay
    iterations = cfg.content_iterations if len(data.contents) > 1 else 0
    bar = tqdm(range(iterations), desc="content network", disable=not progress, mininterval=PROGRESS_INTERVAL)
    for it in bar:
        x, _, content = (t.to(device) for t in windows(data.splits["train"], cfg.window, cfg.content_batch,
                                                        np.random.default_rng([cfg.seed, 1, it])))
        loss = F.cross_entropy(net(losses.views(frames(x))["content"])[0], content)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        bar.set_postfix(loss=f"{loss.item():.3f}", refresh=False)
    net.zero_grad(set_to_none=True)
    net.requires_grad_(False).eval()
    x, _, content = (t.to(device) for t in windows(data.splits["val"], cfg.window, 256,
                                                    np.random.default_rng([cfg.seed, 2])))
    with torch.no_grad():
        logits, _ = net(losses.views(frames(x))["content"])
    info = {"val_window_accuracy": round(float((logits.argmax(-1) == content).float().mean()), 4),
            "window_frames": cfg.window, "iterations": iterations}
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"settings": _settings(cfg), "contents": list(data.contents),
                "model": net.state_dict(), "info": info}, path)
    return net, info
