"""MoST, the motion style transformer (Kim et al. 2024), on the canonical skeleton: style taken from a
reference motion of any action, with its own global translation.

A window of encode() features (``(B, T, 260)``, raw; normalised inside) becomes one token per
body part and frame (:data:`PARTS`: torso, two arms, two legs, and a root token), and:

- :class:`Embedding`: each body part's joints (6D rotation, position, velocity; the feet's contact
  flags on the legs) through a linear layer; the root token is the pelvis's own joint vector (half
  the width) beside the global translation embedding of the ``root`` block (forward-plane
  velocity, pelvis height, yaw rate; the other half).
- :class:`Encoder` (the Siamese motion encoder: one network for the content and the style motion):
  a learned style token per part is put before the frames; blocks of body-part attention (the
  parts of one frame) and temporal attention (the frames, all parts of a frame as one vector),
  each pre-norm with a feed-forward layer. The style token's output is the body-part style feature
  ``S`` ``(B, P, D)``; the frames go through one more block after an instance norm (style
  statistics removed) and give the frame-level content feature ``Y`` ``(B, T, P, D)`` and its
  mean over time ``C`` ``(B, P, D)``.
- :class:`Modulator` (the part-attentive style modulator, PSM): cross-attention from the content
  motion's parts (``C`` of the content motion: queries) to the style motion's parts (its ``C``:
  keys), re-combining the style motion's part features (its ``S``: values), plus a linear path of
  ``S`` and a feed-forward layer: the style vector ``m`` ``(B, P * D)`` for the content motion.
- :class:`Generator`: blocks like the encoder's, each after an AdaIN whose scale and shift come
  from ``m``; heads per part: the limbs' and torso's local rotations, the pelvis's rotation, the
  global translation (pelvis height) and the global velocity (forward-plane velocity and yaw rate
  in the facing frame), so the output is the package's ``[root (4) | rot6d (126)]`` frame with no
  root copied from the input.
- :class:`MoST` puts them together (:meth:`MoST.transfer`); :class:`Step` is the streamed graph
  (content encoder, modulator, generator; the reference's ``S`` and ``C`` given, computed once per
  reference by :class:`StyleFeatures`); :class:`Discriminator` is a one-block transformer of the
  same embedding with a real/fake logit per style.

Against the paper (and why): widths ``dim`` 48 with 4 heads as the paper's (the first model, at 32,
was 1.4-1.6 points lower in style and content at the same 2-hour budget on one CPU core), 2 encoder blocks plus the content block as the paper's code has them, 2 generator blocks
instead of 3, 48-frame windows at 30 fps (1.6 s) instead of 200 at 60 fps (the stream's windows:
their cost per hop and the lookahead), 6D rotations and the package's facing-frame root block
instead of quaternions and world axes; frame positions are a sinusoidal encoding (any window length)
and part positions a learned one, where the paper learns one per frame and part; no dropout (a
short run underfits rather than overfits, and runs resume exactly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.models.style_erd import OUT_ROOT, orthonormal_6d

EPS = 1e-5


@dataclass(frozen=True)
class MostConfig:
    """Network sizes (see the module docstring for the paper's)."""

    styles: tuple[str, ...]
    window: int = 48  # frames at 30 fps
    dim: int = 48  # per body-part token
    heads: int = 4
    enc_blocks: int = 2  # before the content block
    dec_blocks: int = 2
    dis_blocks: int = 1
    ff_expand: float = 1.0  # feed-forward width over the temporal width (P * dim)
    # the generator's heads give a change to the content window's own frames, not the frames
    # themselves (not in the paper; the transfer starts from the input's action)
    residual: bool = False
    n_features: int = 260

    @property
    def n_out(self) -> int:
        return OUT_ROOT + 6 * 21


def tiny(styles: tuple[str, ...]) -> MostConfig:
    """A very small network with the real interface (tests, runtime development)."""
    return MostConfig(styles, window=16, dim=8, heads=2, enc_blocks=1, dec_blocks=1)


# --- body parts ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Part:
    """A body part's token: the feature columns it reads and the output columns it writes."""

    name: str
    joints: tuple[int, ...]  # feature-joint indices (0 = the pelvis)
    contacts: tuple[int, ...]  # columns of encode()'s contact block (absolute)


def _parts() -> tuple[Part, ...]:
    """The canonical skeleton's body parts without the pelvis (the root token has it), then the
    root token."""
    sk = canonical()
    lay = feature_layout(sk)
    joints = list(lay.joints)
    contact = lay.slices["contact"].start
    out = []
    for name, members in sk.parts.items():
        idx = tuple(joints.index(j) for j in members if j != sk.pelvis)
        feet = tuple(contact + k for k, f in enumerate(sk.feet) if f in members)
        out.append(Part(name, idx, feet))
    out.append(Part("root", (0,), ()))
    return tuple(out)


PARTS = _parts()


def _joint_columns(joints: tuple[int, ...]) -> list[int]:
    """encode() columns of each joint's rotation, position and velocity."""
    s = feature_layout().slices
    cols = []
    for k in joints:
        cols += list(range(s["rot6d"].start + 6 * k, s["rot6d"].start + 6 * k + 6))
        cols += list(range(s["pos"].start + 3 * k, s["pos"].start + 3 * k + 3))
        cols += list(range(s["vel"].start + 3 * k, s["vel"].start + 3 * k + 3))
    return cols


def _output_order() -> list[int]:
    """Where each column of the heads' concatenated output goes in ``[root | rot6d]``: the limbs'
    rotations part by part, the pelvis's rotation, the height, the global velocity."""
    order = []
    for part in PARTS[:-1]:
        for k in part.joints:
            order += list(range(OUT_ROOT + 6 * k, OUT_ROOT + 6 * k + 6))
    order += list(range(OUT_ROOT, OUT_ROOT + 6))  # pelvis rotation
    order += [2]  # global translation: pelvis height
    order += [0, 1, 3]  # global velocity: forward-plane velocity, yaw rate
    return order


# --- transformer pieces ----------------------------------------------------------------------

def _sinusoid(frames: int, width: int) -> torch.Tensor:
    """``(frames, width)`` sinusoidal position encoding."""
    position = torch.arange(frames, dtype=torch.float32)[:, None]
    rate = torch.exp(torch.arange(0, width, 2, dtype=torch.float32) * (-math.log(10000.0) / width))
    pe = torch.zeros(frames, width)
    pe[:, 0::2] = torch.sin(position * rate)
    pe[:, 1::2] = torch.cos(position * rate[: width // 2])
    return pe


class Attention(nn.Module):
    """Multi-head attention from ``query`` ``(N, L, C)`` to ``key`` / ``value`` ``(N, M, C)``
    (self-attention when only the query is given)."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"width {dim} does not split into {heads} heads")
        self.heads, self.scale = heads, (dim // heads) ** -0.5
        self.q, self.k, self.v = (nn.Linear(dim, dim, bias=False) for _ in range(3))
        self.proj = nn.Linear(dim, dim)

    def forward(self, query: torch.Tensor, key: torch.Tensor | None = None,
                value: torch.Tensor | None = None) -> torch.Tensor:
        """Tokens ``(..., L, C)`` along the second-last axis (any leading axes)."""
        key = query if key is None else key
        value = key if value is None else value
        q, k, v = (lin(x).unflatten(-1, (self.heads, -1)).transpose(-3, -2)
                   for lin, x in ((self.q, query), (self.k, key), (self.v, value)))
        weights = torch.softmax((q @ k.transpose(-2, -1)) * self.scale, dim=-1)
        return self.proj((weights @ v).transpose(-3, -2).flatten(-2))


class FeedForward(nn.Sequential):
    def __init__(self, dim: int, hidden: int) -> None:
        super().__init__(nn.Linear(dim, hidden), nn.GELU(), nn.Linear(hidden, dim))


class Block(nn.Module):
    """Body-part attention over the parts of each frame, then temporal attention over the frames
    (all parts of a frame as one vector), then a feed-forward layer; pre-norm residuals. Tokens
    ``(B, T, P, D)``."""

    def __init__(self, cfg: MostConfig) -> None:
        super().__init__()
        p, d = len(PARTS), cfg.dim
        wide = p * d
        self.part_pos = nn.Parameter(torch.zeros(p, d))
        self.norm_part, self.part_attn = nn.LayerNorm(d), Attention(d, cfg.heads)
        self.norm_time, self.time_attn = nn.LayerNorm(wide), Attention(wide, cfg.heads)
        self.norm_ff, self.ff = nn.LayerNorm(wide), FeedForward(wide, max(1, int(wide * cfg.ff_expand)))
        rate = torch.exp(torch.arange(0, wide, 2, dtype=torch.float32) * (-math.log(10000.0) / wide))
        self.register_buffer("frame_rate", rate, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        p, d = x.shape[-2:]
        h = x + self.part_pos  # (B, T, P, D)
        h = h + self.part_attn(self.norm_part(h))
        h = h.flatten(2)  # (B, T, P D)
        h = h + self.frame_encoding(h)
        h = h + self.time_attn(self.norm_time(h))
        h = h + self.ff(self.norm_ff(h))
        return h.unflatten(2, (p, d))

    def frame_encoding(self, h: torch.Tensor) -> torch.Tensor:
        """``(T, P D)`` sines and cosines of each frame's index, made from ``h`` ``(B, T, P D)``'s
        length inside the graph (an ONNX graph of any window length)."""
        frame = torch.cumsum(h[0, :, :1] * 0.0 + 1.0, dim=0) - 1.0  # (T, 1): 0, 1, 2... (from h: not folded)
        angle = frame * self.frame_rate
        return torch.cat([torch.sin(angle), torch.cos(angle)], dim=-1)


def instance_norm(x: torch.Tensor) -> torch.Tensor:
    """Tokens ``(B, T, P, D)`` normalised per channel over frames and parts (each motion's own
    statistics: its style's first and second moments taken out)."""
    mean = x.mean(dim=(1, 2), keepdim=True)
    var = (x - mean).pow(2).mean(dim=(1, 2), keepdim=True)
    return (x - mean) / torch.sqrt(var + EPS)


class Embedding(nn.Module):
    """Raw encode() features ``(B, T, F)`` -> body-part tokens ``(B, T, P, D)``, normalised with
    the train statistics (buffers)."""

    def __init__(self, cfg: MostConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        limbs = PARTS[:-1]
        for k, part in enumerate(limbs):
            self.register_buffer(f"cols{k}", torch.tensor(_joint_columns(part.joints) + list(part.contacts)),
                                 persistent=False)
        self.limbs = nn.ModuleList(nn.Linear(len(_joint_columns(p.joints)) + len(p.contacts), cfg.dim)
                                   for p in limbs)
        root = feature_layout().slices["root"]
        self.register_buffer("pelvis_cols", torch.tensor(_joint_columns((0,))), persistent=False)
        self.register_buffer("global_cols", torch.arange(root.start, root.stop), persistent=False)
        self.pelvis = nn.Linear(12, cfg.dim - cfg.dim // 2)
        self.global_ = nn.Linear(OUT_ROOT, cfg.dim // 2)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        x = (features - self.mean) / self.std
        tokens = [lin(x[..., getattr(self, f"cols{k}")]) for k, lin in enumerate(self.limbs)]
        tokens.append(torch.cat([self.pelvis(x[..., self.pelvis_cols]),
                                 self.global_(x[..., self.global_cols])], dim=-1))
        return torch.stack(tokens, dim=2)


class Encoder(nn.Module):
    """The Siamese motion encoder: raw features ``(B, T, F)`` -> style feature ``S`` ``(B, P, D)``,
    content feature ``Y`` ``(B, T, P, D)`` and its mean over time ``C`` ``(B, P, D)``."""

    def __init__(self, cfg: MostConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.embed = Embedding(cfg, mean, std)
        self.style_token = nn.Parameter(0.02 * torch.randn(len(PARTS), cfg.dim))
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.enc_blocks))
        self.content = Block(cfg)

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        x = self.embed(features)
        token = self.style_token.expand(x.shape[0], 1, -1, -1)
        h = torch.cat([token, x], dim=1)
        for block in self.blocks:
            h = block(h)
        y = self.content(instance_norm(h[:, 1:]))
        return h[:, 0], y, y.mean(dim=1)


class Modulator(nn.Module):
    """The part-attentive style modulator: ``(C`` of the content motion, ``C`` and ``S`` of the
    style motion, each ``(B, P, D))`` -> the style vector ``m`` ``(B, P * D)``."""

    def __init__(self, cfg: MostConfig) -> None:
        super().__init__()
        p, d = len(PARTS), cfg.dim
        self.part_pos = nn.Parameter(_sinusoid(p, d).clone())
        self.norm_q, self.norm_k, self.norm_v = nn.LayerNorm(d), nn.LayerNorm(d), nn.LayerNorm(d)
        self.cross = Attention(d, cfg.heads)
        self.linear = nn.Linear(p * d, p * d)
        self.norm_ff, self.ff = nn.LayerNorm(p * d), FeedForward(p * d, p * d)

    def forward(self, content: torch.Tensor, style_content: torch.Tensor, style: torch.Tensor
                ) -> torch.Tensor:
        q, k, v = (x + self.part_pos for x in (content, style_content, style))
        m = self.cross(self.norm_q(q), self.norm_k(k), self.norm_v(v)).flatten(1) + self.linear(v.flatten(1))
        return m + self.ff(self.norm_ff(m))


class AdaIN(nn.Module):
    """Instance norm of tokens ``(B, T, P, D)`` whose per-channel scale and shift come from ``m``."""

    def __init__(self, cfg: MostConfig) -> None:
        super().__init__()
        self.fc = nn.Linear(len(PARTS) * cfg.dim, 2 * cfg.dim)

    def forward(self, x: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        gamma, beta = self.fc(m)[:, None, None].chunk(2, dim=-1)
        return (1 + gamma) * instance_norm(x) + beta


class Generator(nn.Module):
    """``(Y (B, T, P, D), m (B, P * D))`` and the content window's raw features ``(B, T, F)`` ->
    raw ``[root | rot6d]`` frames ``(B, T, 130)``, 6D rotations orthonormal. With ``residual``, the
    heads add a change (in train-std units) to the content window's own frames and start at zero,
    so an untrained generator returns its input."""

    def __init__(self, cfg: MostConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.adain = nn.ModuleList(AdaIN(cfg) for _ in range(cfg.dec_blocks))
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.dec_blocks))
        self.norm = nn.LayerNorm(cfg.dim)
        self.limbs = nn.ModuleList(nn.Linear(cfg.dim, 6 * len(p.joints)) for p in PARTS[:-1])
        self.pelvis = nn.Linear(cfg.dim, 6)  # local motion of the root joint
        self.translation = nn.Linear(cfg.dim, 1)  # global translation: pelvis height
        self.velocity = nn.Linear(cfg.dim, 3)  # global velocity: vx, vz, yaw rate
        order = torch.tensor(_output_order())
        self.register_buffer("unorder", torch.argsort(order), persistent=False)
        out = slice(0, cfg.n_out)
        self.register_buffer("out_mean", torch.as_tensor(mean[out], dtype=torch.float32))
        self.register_buffer("out_std", torch.as_tensor(std[out], dtype=torch.float32))
        self.residual = cfg.residual
        if self.residual:
            for head in (*self.limbs, self.pelvis, self.translation, self.velocity):
                nn.init.zeros_(head.weight)
                nn.init.zeros_(head.bias)

    def forward(self, y: torch.Tensor, m: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
        h = y
        for adain, block in zip(self.adain, self.blocks):
            h = block(adain(h, m))
        h = self.norm(h)
        root = h[:, :, -1]
        heads = [lin(h[:, :, k]) for k, lin in enumerate(self.limbs)]
        heads += [self.pelvis(root), self.translation(root), self.velocity(root)]
        start = base[..., : self.out_mean.shape[0]] if self.residual else self.out_mean
        out = start + self.out_std * torch.cat(heads, dim=-1)[..., self.unorder]
        rot6d = orthonormal_6d(out[..., OUT_ROOT:].unflatten(-1, (-1, 6))).flatten(-2)
        return torch.cat([out[..., :OUT_ROOT], rot6d], dim=-1)


class MoST(nn.Module):
    """The encoder, modulator and generator of one model (what is trained and exported)."""

    def __init__(self, cfg: MostConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = Encoder(cfg, mean, std)
        self.modulator = Modulator(cfg)
        self.generator = Generator(cfg, mean, std)

    def transfer(self, content: tuple[torch.Tensor, ...], style: tuple[torch.Tensor, ...],
                 base: torch.Tensor) -> torch.Tensor:
        """The content motion's encoding ``(S, Y, C)`` restyled like the style motion's; ``base``:
        the content motion's raw features (what a residual generator changes)."""
        _, y, c = content
        s_style, _, c_style = style
        return self.generator(y, self.modulator(c, c_style, s_style), base)

    def forward(self, content: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """Raw features of a content and a style window ``(B, T, F)`` -> the transfer ``(B, T, 130)``."""
        return self.transfer(self.encoder(content), self.encoder(style), content)


class Step(nn.Module):
    """The streamed graph: a window of raw features ``(B, T, F)``, the reference's style feature
    ``S`` and mean content feature ``C`` ``(B, P, D)`` (:class:`StyleFeatures`, once per reference)
    and ``alpha`` ``(B, 1)`` -> the stylized window ``(B, T, 130)``. Alpha moves the style vector from
    the window's own (alpha 0: the reconstruction) to the reference's."""

    def __init__(self, model: MoST) -> None:
        super().__init__()
        self.model = model

    def forward(self, features: torch.Tensor, style: torch.Tensor, pooled: torch.Tensor,
                alpha: torch.Tensor) -> torch.Tensor:
        s, y, c = self.model.encoder(features)
        own = self.model.modulator(c, c, s)
        ref = self.model.modulator(c, pooled, style)
        return self.model.generator(y, own + alpha * (ref - own), features)


class StyleFeatures(nn.Module):
    """A style motion's window ``(B, T, F)`` -> its style feature ``S`` and mean content feature
    ``C`` ``(B, P, D)`` (the reference side of the Siamese encoder)."""

    def __init__(self, model: MoST) -> None:
        super().__init__()
        self.encoder = model.encoder

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        s, _, c = self.encoder(features)
        return s, c


class Discriminator(nn.Module):
    """Raw features ``(B, T, F)`` -> one real/fake logit per style ``(B, S)``: the same embedding,
    a class token per part, ``dis_blocks`` blocks, a head on the tokens."""

    def __init__(self, cfg: MostConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        p, d = len(PARTS), cfg.dim
        self.embed = Embedding(cfg, mean, std)
        self.token = nn.Parameter(0.02 * torch.randn(p, d))
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.dis_blocks))
        self.head = nn.Sequential(nn.LayerNorm(p * d), nn.Linear(p * d, d), nn.LeakyReLU(0.2),
                                  nn.Linear(d, len(cfg.styles)))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        x = self.embed(features)
        h = torch.cat([self.token.expand(x.shape[0], 1, -1, -1), x], dim=1)
        for block in self.blocks:
            h = block(h)
        return self.head(h[:, 0].flatten(1))


def n_parameters(module: nn.Module) -> int:
    """Trainable and fixed weights of ``module`` (the card's architecture record)."""
    return int(sum(p.numel() for p in module.parameters()))

