"""Diverse motion stylization with ST-GCN (Park et al. 2021, Table 3), on the canonical skeleton.

A window of encode() features (``(B, T, 260)``, raw) is laid out per joint node
(``core.graph.node_scatter``), normalised, and run through spatial-temporal graph convolutions:
the neighbourhood of each node is split into self / parent / children with one weight each, then
a temporal convolution of kernel 3. Graph pooling averages clusters of joints inside a body part
(21 -> 11 -> 5 nodes) while time halves; unpooling copies clusters back and interpolates time.

- :class:`Generator`: 1x1 conv -> two ST residual blocks with instance norm and pooling -> two ST
  AdaIN residual blocks with unpooling (a skip from the first encoder block) -> 1x1 conv. Unlike
  the paper it predicts a change to the input's ``[root | rot6d]`` blocks (zero at start), so it
  reproduces the input before it learns to restyle, and it outputs the root block too (root
  velocity, height, yaw rate): styles change speed and turns.
- :class:`MappingNetwork`: noise ``z`` (16) and style weights -> style code (64).
- :class:`StyleEncoder`: a shared ST trunk, one style-code head per style, and (an addition) a
  style classifier head, so a reference clip of unknown style picks its own head. The trunk
  averages over time, so any clip of at least one window's length can be encoded.
- :class:`Discriminator`: the same trunk shape with one real/fake output per style.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion_style_ros.core.graph import (
    ALL_CHANNELS,
    MOTION_CHANNELS,
    hierarchy,
    node_scatter,
)
from motion_style_ros.models.style_erd import OUT_ROOT, orthonormal_6d

SLOPE = 0.2  # leaky ReLU
OUT_CHANNELS = 10  # per node: rot6d (6) + the root block (4, read from the pelvis node only)


@dataclass(frozen=True)
class StgcnConfig:
    """Network sizes. The paper's widths are (64, 128, 256), a 1024-wide mapping network and
    240-frame clips; these are scaled down to train in about two hours on 2 CPU cores."""

    styles: tuple[str, ...]
    window: int = 48  # frames (a multiple of 4: time halves twice)
    widths: tuple[int, int, int] = (32, 64, 128)
    style_dim: int = 64
    latent_dim: int = 16
    mapping_hidden: int = 256
    n_features: int = 260

    @property
    def n_out(self) -> int:
        return OUT_ROOT + 6 * 21


def tiny(styles: tuple[str, ...]) -> StgcnConfig:
    """A very small network with the real interface (tests, runtime development)."""
    return StgcnConfig(styles, window=32, widths=(8, 8, 16), style_dim=8, mapping_hidden=16)


class _Graphs(nn.Module):
    """Adjacency of each level and the pooling matrices, as buffers shared by a network's blocks."""

    def __init__(self) -> None:
        super().__init__()
        adjacency, pools = hierarchy()
        for k, a in enumerate(adjacency):
            self.register_buffer(f"a{k}", torch.from_numpy(a.transpose(0, 2, 1).copy()))
        for k, p in enumerate(pools):
            self.register_buffer(f"pool{k}", torch.from_numpy(p))
            self.register_buffer(f"unpool{k}", torch.from_numpy((p > 0).T.astype(np.float32).copy()))

    def sizes(self) -> list[int]:
        return [self.a0.shape[-1], self.a1.shape[-1], self.a2.shape[-1]]


class GraphConv(nn.Module):
    """``(B, C, T, N)`` -> ``(B, C', T, N)``: one 1x1 weight per partition subset, summed over each
    node's subset neighbours with the normalised adjacency (``a``: ``(3, N, N)`` transposed)."""

    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.c_out = c_out
        self.conv = nn.Conv2d(c_in, 3 * c_out, 1)

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        y = self.conv(x)
        y = y.unflatten(1, (3, self.c_out))  # (B, 3, C', T, N)
        return (y @ a[None, :, None]).sum(dim=1)


class STConv(nn.Module):
    """Graph convolution, optional pooling, leaky ReLU, temporal convolution (kernel 3)."""

    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.graph = GraphConv(c_in, c_out)
        self.time = nn.Conv2d(c_out, c_out, (3, 1), padding=(1, 0))

    def forward(self, x: torch.Tensor, a: torch.Tensor, pool: torch.Tensor | None = None) -> torch.Tensor:
        x = self.graph(x, a)
        if pool is not None:
            x = _pool(x, pool)
        return self.time(F.leaky_relu(x, SLOPE))


def _pool(x: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """Average clusters of nodes and pairs of frames."""
    return F.avg_pool2d(x @ matrix, (2, 1))


def _unpool(x: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """Copy clusters back onto their nodes and interpolate time linearly to twice the frames."""
    return F.interpolate(x @ matrix, scale_factor=(2.0, 1.0), mode="bilinear", align_corners=False)


class ResBlock(nn.Module):
    """ST residual block that pools from level ``k`` to ``k + 1`` (instance norm optional)."""

    def __init__(self, c_in: int, c_out: int, level: int, norm: bool) -> None:
        super().__init__()
        self.level = level
        self.conv1, self.conv2 = STConv(c_in, c_in), STConv(c_in, c_out)
        self.shortcut = nn.Conv2d(c_in, c_out, 1, bias=False)
        self.norm1 = nn.InstanceNorm2d(c_in, affine=True) if norm else nn.Identity()
        self.norm2 = nn.InstanceNorm2d(c_in, affine=True) if norm else nn.Identity()

    def forward(self, x: torch.Tensor, g: _Graphs) -> torch.Tensor:
        k = self.level
        pool = getattr(g, f"pool{k}")
        h = self.conv1(F.leaky_relu(self.norm1(x), SLOPE), getattr(g, f"a{k}"), pool)
        h = self.conv2(F.leaky_relu(self.norm2(h), SLOPE), getattr(g, f"a{k + 1}"))
        return (_pool(self.shortcut(x), pool) + h) / math.sqrt(2)


class AdaIN(nn.Module):
    """Instance norm whose scale and shift come from the style code."""

    def __init__(self, style_dim: int, channels: int) -> None:
        super().__init__()
        self.norm = nn.InstanceNorm2d(channels, affine=False)
        self.fc = nn.Linear(style_dim, 2 * channels)

    def forward(self, x: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        gamma, beta = self.fc(s)[:, :, None, None].chunk(2, dim=1)
        return (1 + gamma) * self.norm(x) + beta


class AdaINResBlock(nn.Module):
    """ST residual block with AdaIN that unpools from level ``k + 1`` to ``k``."""

    def __init__(self, c_in: int, c_out: int, level: int, style_dim: int) -> None:
        super().__init__()
        self.level = level
        self.conv1, self.conv2 = STConv(c_in, c_out), STConv(c_out, c_out)
        self.shortcut = nn.Conv2d(c_in, c_out, 1, bias=False)
        self.norm1, self.norm2 = AdaIN(style_dim, c_in), AdaIN(style_dim, c_out)

    def forward(self, x: torch.Tensor, s: torch.Tensor, g: _Graphs) -> torch.Tensor:
        k = self.level
        unpool, a = getattr(g, f"unpool{k}"), getattr(g, f"a{k}")
        h = _unpool(F.leaky_relu(self.norm1(x, s), SLOPE), unpool)
        h = self.conv1(h, a)
        h = self.conv2(F.leaky_relu(self.norm2(h, s), SLOPE), a)
        return (self.shortcut(_unpool(x, unpool)) + h) / math.sqrt(2)


class _Input(nn.Module):
    """Raw encode() features ``(B, T, F)`` -> normalised node channels ``(B, C, T, N)``."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, channels: int) -> None:
        super().__init__()
        self.channels = channels
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.register_buffer("scatter", torch.from_numpy(node_scatter()))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        x = ((features - self.mean) / self.std) @ self.scatter
        x = x.unflatten(-1, (-1, ALL_CHANNELS))[..., : self.channels]  # (B, T, N, C)
        return x.permute(0, 3, 1, 2)


class Generator(nn.Module):
    """``(features (B, T, 260) raw, code (B, style_dim))`` -> ``(B, T, 130)`` raw ``[root | rot6d]``
    with orthonormal 6D rotations; ``T`` a multiple of 4."""

    def __init__(self, cfg: StgcnConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        w1, w2, w3 = cfg.widths
        self.graphs = _Graphs()
        self.input = _Input(mean, std, ALL_CHANNELS)
        self.first = nn.Conv2d(ALL_CHANNELS, w1, 1)
        self.enc1, self.enc2 = ResBlock(w1, w2, 0, True), ResBlock(w2, w3, 1, True)
        self.dec1 = AdaINResBlock(w3, w2, 1, cfg.style_dim)
        self.skip = nn.Sequential(nn.InstanceNorm2d(w2, affine=False), nn.Conv2d(w2, w2, 1))
        self.dec2 = AdaINResBlock(w2, w1, 0, cfg.style_dim)
        self.last = nn.Conv2d(w1, OUT_CHANNELS, 1)
        nn.init.zeros_(self.last.weight)  # starts as the identity: output = input
        nn.init.zeros_(self.last.bias)
        out = slice(0, cfg.n_out)
        self.register_buffer("out_mean", torch.as_tensor(mean[out], dtype=torch.float32))
        self.register_buffer("out_std", torch.as_tensor(std[out], dtype=torch.float32))

    def forward(self, features: torch.Tensor, code: torch.Tensor) -> torch.Tensor:
        g = self.graphs
        h1 = self.enc1(self.first(self.input(features)), g)
        h = self.dec1(self.enc2(h1, g), code, g) + self.skip(h1)
        delta = self.last(self.dec2(h, code, g)).permute(0, 2, 3, 1)  # (B, T, N, 10)
        change = torch.cat([delta[..., 0, 6:], delta[..., :6].flatten(-2)], dim=-1)
        out = features[..., : self.cfg.n_out] + change * self.out_std
        rot6d = orthonormal_6d(out[..., OUT_ROOT:].unflatten(-1, (-1, 6))).flatten(-2)
        return torch.cat([out[..., :OUT_ROOT], rot6d], dim=-1)


class MappingNetwork(nn.Module):
    """``(z (B, latent_dim), style weights (B, S))`` -> style code ``(B, style_dim)`` in (-1, 1)."""

    def __init__(self, cfg: StgcnConfig) -> None:
        super().__init__()
        h = cfg.mapping_hidden
        self.z = nn.Sequential(nn.Linear(cfg.latent_dim, h // 2), nn.ReLU())
        self.y = nn.Sequential(nn.Linear(len(cfg.styles), h // 2), nn.ReLU())
        self.shared = nn.Sequential(nn.Linear(h, h), nn.ReLU(), nn.Linear(h, h), nn.ReLU(),
                                    nn.Linear(h, cfg.style_dim), nn.Tanh())

    def forward(self, z: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        return self.shared(torch.cat([self.z(z), self.y(style)], dim=-1))


class _Trunk(nn.Module):
    """Motion channels (no contacts) -> one vector per clip: two pooling ST blocks, a convolution
    over the 5 body-part nodes, the mean over time."""

    def __init__(self, cfg: StgcnConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        w1, w2, w3 = cfg.widths
        self.graphs = _Graphs()
        self.input = _Input(mean, std, MOTION_CHANNELS)
        self.first = nn.Conv2d(MOTION_CHANNELS, w1, 1)
        self.block1, self.block2 = ResBlock(w1, w2, 0, False), ResBlock(w2, w3, 1, False)
        self.parts = nn.Conv2d(w3, w3, (1, self.graphs.sizes()[2]))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        h = self.block2(self.block1(self.first(self.input(features)), self.graphs), self.graphs)
        h = self.parts(F.leaky_relu(h, SLOPE))  # (B, C, T/4, 1)
        return F.leaky_relu(h.mean(dim=(2, 3)), SLOPE)


class StyleEncoder(nn.Module):
    """``features (B, T, 260)`` raw -> style codes of every style's head ``(B, S, style_dim)`` and
    style logits ``(B, S)``."""

    def __init__(self, cfg: StgcnConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        self.trunk = _Trunk(cfg, mean, std)
        self.heads = nn.Linear(cfg.widths[2], len(cfg.styles) * cfg.style_dim)
        self.classifier = nn.Linear(cfg.widths[2], len(cfg.styles))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.trunk(features)
        return self.heads(h).unflatten(-1, (len(self.cfg.styles), -1)), self.classifier(h)


class Discriminator(nn.Module):
    """``features (B, T, 260)`` raw -> one real/fake logit per style ``(B, S)``."""

    def __init__(self, cfg: StgcnConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.trunk = _Trunk(cfg, mean, std)
        self.out = nn.Linear(cfg.widths[2], len(cfg.styles))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.out(self.trunk(features))


def pick(codes: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
    """The code of each row's style: ``codes (B, S, D)``, ``style (B,)`` indices -> ``(B, D)``."""
    return codes[torch.arange(len(style)), style]
