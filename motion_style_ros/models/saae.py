"""The sequence adversarial autoencoder of the fourth seed (ESANN 2018, "Adversarial learning for
style transfer between motion capture sequences"): plain SAAE, Model1 and Model2, on windows of
``core.features.encode()`` frames of the canonical skeleton.

- :class:`Encoder`: a bidirectional GRU over a window of normalised features; its two final states
  give the **content code** (``content_dim``), which a prior discriminator pushes towards N(0, I) so
  that the decoder alone is a generator, and (Model2 only) a low-dimensional **style code**
  (``style_dim``, 2 to 5 in the paper).
- :class:`Decoder`: a GRU whose initial state and every step's input are the content code, the
  style input and the frame's position in the window (``t / window``, so any length can be asked
  for); it outputs ``[root | rot6d]`` frames in raw units with orthonormal 6D rotations, like the
  ST-GCN generator. The style input is what tells the variants apart: a one-hot label (Model1), the
  style code (Model2), or one constant 0 (the plain SAAE, which has no style input; the one-wide
  zero keeps every variant's ONNX interface the same).
- :class:`Critic`: the prior discriminator (code -> real/fake logit) and the style discriminators
  (code -> style logits). The one on the content code is read through
  :func:`~motion_style_ros.models.style_erd.reverse` (a gradient-reversal layer, Ganin and
  Lempitsky 2015): it learns to recover the style while the
  encoder learns to hide it. Model2's second one reads the style code with its gradient as it is,
  so the style code carries the style; it is exported with the style encoder as its classifier.

Sizes (:class:`SaaeConfig` defaults) and why. The paper gives none but its windows: 200 frames of
~120 fps Emilya motion (1.7 s), 70-dim frames. Here a window is 48 frames at 30 fps (1.6 s; the
ST-GCN backend's window, so both stream with the same hop and lookahead), frames are 260 features
in and 130 out. A GRU of 256 units each way in the encoder and one of 256 in the decoder with a
32-dim content code come to 1.1 M parameters; the critics are small MLPs (128 wide). At batch 32
on one torch thread pinned to one core (the MoST run held the other) this trains at 4.9 iterations
a second: the shipped Model2 made 29,553 iterations, some 9.5 x 10^5 windows, in 100 minutes (the
paper saw 8 x 10^4 windows per epoch). GRUs rather than LSTMs: a third fewer
weights for the same width, and the trainer's time goes into the recurrences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion_style_ros.models.style_erd import OUT_ROOT, orthonormal_6d

VARIANTS = ("saae", "model1", "model2")
SLOPE = 0.2  # leaky ReLU of the critics


@dataclass(frozen=True)
class SaaeConfig:
    """Network sizes (see the module docstring for why these)."""

    styles: tuple[str, ...]
    variant: str = "model2"
    window: int = 48
    hidden: int = 256  # GRU units: the encoder's each way, the decoder's
    content_dim: int = 32
    style_dim: int = 5  # Model2's style code
    critic_hidden: int = 128
    n_features: int = 260

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"variant {self.variant!r}; one of {', '.join(VARIANTS)}")

    @property
    def n_out(self) -> int:
        return OUT_ROOT + 6 * 21

    @property
    def style_width(self) -> int:
        """The decoder's style input: one-hot (Model1), style code (Model2), one 0 (plain SAAE)."""
        return {"model1": len(self.styles), "model2": self.style_dim, "saae": 1}[self.variant]


def tiny(styles: tuple[str, ...], variant: str = "model2", **changes) -> SaaeConfig:
    """A very small network with the real interface (tests, runtime development)."""
    return SaaeConfig(styles, variant, **{"window": 16, "hidden": 16, "content_dim": 6, "style_dim": 3,
                                          "critic_hidden": 16, **changes})


class Encoder(nn.Module):
    """``features (B, T, 260)`` raw -> content code ``(B, content_dim)`` and style code ``(B,
    style_dim)`` (Model2; other variants' is ``(B, 0)``)."""

    def __init__(self, cfg: SaaeConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.rnn = nn.GRU(cfg.n_features, cfg.hidden, batch_first=True, bidirectional=True)
        self.content = nn.Linear(2 * cfg.hidden, cfg.content_dim)
        self.style = nn.Linear(2 * cfg.hidden, cfg.style_dim) if cfg.variant == "model2" else None

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        _, h = self.rnn((features - self.mean) / self.std)  # h: (2, B, hidden), both directions' last
        h = torch.cat([h[0], h[1]], dim=-1)
        return self.content(h), (h[:, :0] if self.style is None else self.style(h))


class Decoder(nn.Module):
    """``(content (B, content_dim), style (B, style_width), position (B, T))`` -> ``(B, T, 130)``
    raw ``[root | rot6d]``, 6D rotations orthonormal. ``position``: each frame's index over the
    trained window (``t / window``)."""

    def __init__(self, cfg: SaaeConfig, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        code = cfg.content_dim + cfg.style_width
        self.start = nn.Linear(code, cfg.hidden)
        self.rnn = nn.GRU(code + 1, cfg.hidden, batch_first=True)
        self.out = nn.Linear(cfg.hidden, cfg.n_out)
        out = slice(0, cfg.n_out)
        self.register_buffer("out_mean", torch.as_tensor(mean[out], dtype=torch.float32))
        self.register_buffer("out_std", torch.as_tensor(std[out], dtype=torch.float32))

    def forward(self, content: torch.Tensor, style: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
        code = torch.cat([content, style], dim=-1)
        steps = torch.cat([code[:, None, :].expand(-1, position.shape[1], -1), position[..., None]], dim=-1)
        y, _ = self.rnn(steps, torch.tanh(self.start(code))[None])
        out = self.out(y) * self.out_std + self.out_mean
        rot6d = orthonormal_6d(out[..., OUT_ROOT:].unflatten(-1, (-1, 6))).flatten(-2)
        return torch.cat([out[..., :OUT_ROOT], rot6d], dim=-1)


class Critic(nn.Module):
    """A code ``(B, D)`` -> ``(B, outputs)`` logits: the prior discriminator (1 output) or a style
    discriminator (one per style)."""

    def __init__(self, inputs: int, hidden: int, outputs: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(inputs, hidden), nn.LeakyReLU(SLOPE), nn.Linear(hidden, hidden),
                                 nn.LeakyReLU(SLOPE), nn.Linear(hidden, outputs))

    def forward(self, code: torch.Tensor) -> torch.Tensor:
        return self.net(code)


class ContentGraph(nn.Module):
    """The encoder as exported: ``features`` -> ``content``."""

    def __init__(self, encoder: Encoder) -> None:
        super().__init__()
        self.encoder = encoder

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.encoder(features)[0]


class StyleGraph(nn.Module):
    """Model2's style encoder as exported: ``features`` -> ``style_code`` and the style classifier's
    ``logits`` on it (which style a reference clip is)."""

    def __init__(self, encoder: Encoder, classifier: Critic) -> None:
        super().__init__()
        self.encoder, self.classifier = encoder, classifier

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        code = self.encoder(features)[1]
        return code, self.classifier(code)


def positions(frames: int, window: int, batch: int = 1) -> torch.Tensor:
    """The decoder's ``position`` input for ``frames`` frames: ``(batch, frames)``."""
    return (torch.arange(frames, dtype=torch.float32) / window).expand(batch, -1)


def style_input(cfg: SaaeConfig, style: torch.Tensor, style_code: torch.Tensor | None = None) -> torch.Tensor:
    """The decoder's style input for style indices ``(B,)``: one-hot (Model1), the given style code
    (Model2), one 0 (plain SAAE)."""
    if cfg.variant == "model1":
        return F.one_hot(style, len(cfg.styles)).float()
    if cfg.variant == "model2":
        assert style_code is not None
        return style_code
    return torch.zeros(len(style), 1, device=style.device)
