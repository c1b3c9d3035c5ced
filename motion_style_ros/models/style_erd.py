"""Style-ERD (Tao et al., CVPR 2022): an online stylizer, one frame in, one stylized frame out.

Encoder MLP -> recurrent module -> decoder MLP conditioned on the target style. The recurrent module
is a neutral LSTM stack plus one residual LSTM stack per non-neutral style; the target style's
residual is added to the neutral output. Every stack has a learned initial state. The neutral style
(``normal`` in Bandai Namco) has no residual branch: it *is* the neutral branch, so ``alpha = 0``
(residual off, decoder conditioned on the neutral style) and "target = neutral" are one output.

Unlike the paper, neither the encoder nor the initial state sees the input's style or content
label: a live stream has neither. The encoder has to normalise the input frame's style itself.

Also here: the two critics used only while training, the FT-Att discriminator and the content
network (instance-normalised, the perceptual loss's feature extractor).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import torch
from torch import nn

OUT_ROOT = 4  # output = [root (4) | rot6d (6 per joint)], the layout of encode()'s first two blocks


@dataclass(frozen=True)
class ErdConfig:
    """Network sizes, the shipped model's by default (the trainer's config takes them from here).
    The paper's are encoder (64, 32), 6 neutral + 4 style LSTM layers of width 32, decoder (58, 86,
    128): on 2 CPU cores those deep stacks had barely started to reconstruct after 300 iterations
    while these were within a few centimetres (pos loss 0.94 against 0.08), and the exported step
    (:class:`StepGraph`) runs every stack's layers as one batched product, so the stacks need one
    depth."""

    styles: tuple[str, ...]
    neutral: str = "normal"
    n_features: int = 260
    n_joints: int = 21
    encoder: tuple[int, ...] = (128,)  # hidden widths before the latent
    latent: int = 64  # latent code and LSTM width
    neutral_layers: int = 2
    style_layers: int = 2
    decoder: tuple[int, ...] = (128, 128)

    @property
    def n_out(self) -> int:
        return OUT_ROOT + 6 * self.n_joints

    @property
    def branch_styles(self) -> tuple[str, ...]:
        """Styles with a residual branch, in the order of ``styles``."""
        return tuple(s for s in self.styles if s != self.neutral)

    @property
    def state_size(self) -> int:
        layers = self.neutral_layers + len(self.branch_styles) * self.style_layers
        return 2 * layers * self.latent


def tiny(styles: tuple[str, ...], neutral: str = "normal") -> ErdConfig:
    """A very small network with the real interface (tests, runtime development)."""
    return ErdConfig(styles, neutral, encoder=(16,), latent=8, neutral_layers=2, style_layers=2,
                     decoder=(16,))


def _mlp(sizes: list[int], final_activation: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if final_activation or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def orthonormal_6d(d6: torch.Tensor) -> torch.Tensor:
    """Gram-Schmidt on each 6D rotation ``(..., 6)``: the first two columns of a rotation matrix,
    the convention of ``core.rotations.to_6d``."""
    x = nn.functional.normalize(d6[..., :3], dim=-1, eps=1e-8)
    b = d6[..., 3:] - (x * d6[..., 3:]).sum(-1, keepdim=True) * x
    y = nn.functional.normalize(b, dim=-1, eps=1e-8)
    return torch.cat([x, y], dim=-1)


class StyleERD(nn.Module):
    """The generator. Inputs and outputs are raw feature units; normalisation lives in buffers.

    State layout (flat, per performer): for the neutral stack, then each branch in ``branch_styles``
    order: ``h`` (layers, latent) then ``c`` (layers, latent).
    """

    def __init__(self, cfg: ErdConfig, in_mean: np.ndarray, in_std: np.ndarray,
                 out_mean: np.ndarray, out_std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        for name, value in (("in_mean", in_mean), ("in_std", in_std),
                            ("out_mean", out_mean), ("out_std", out_std)):
            self.register_buffer(name, torch.as_tensor(np.asarray(value), dtype=torch.float32))
        n_styles = len(cfg.styles)
        self.register_buffer("neutral_onehot", torch.eye(n_styles)[cfg.styles.index(cfg.neutral)])
        # style column of each branch
        self.register_buffer("branch_columns", torch.tensor(
            [cfg.styles.index(s) for s in cfg.branch_styles], dtype=torch.int64), persistent=False)
        self.encoder = _mlp([cfg.n_features, *cfg.encoder, cfg.latent], final_activation=False)
        self.stacks = nn.ModuleList(
            [nn.LSTM(cfg.latent, cfg.latent, cfg.neutral_layers, batch_first=True)]
            + [nn.LSTM(cfg.latent, cfg.latent, cfg.style_layers, batch_first=True)
               for _ in cfg.branch_styles]
        )
        self.initial = nn.ParameterList(
            [nn.Parameter(torch.zeros(2, lstm.num_layers, cfg.latent)) for lstm in self.stacks]
        )
        self.decoder = _mlp([cfg.latent + n_styles, *cfg.decoder, cfg.n_out], final_activation=False)

    # --- state -----------------------------------------------------------------------------------

    def initial_state(self, batch: int) -> torch.Tensor:
        """The learned initial state, ``(batch, state_size)``."""
        flat = torch.cat([p.reshape(-1) for p in self.initial])
        return flat.expand(batch, -1)

    def _unpack(self, state: torch.Tensor) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Flat ``(B, N)`` -> per stack ``(h, c)`` each ``(layers, B, latent)``."""
        out, start = [], 0
        for lstm in self.stacks:
            n = lstm.num_layers * self.cfg.latent
            h = state[:, start : start + n].reshape(-1, lstm.num_layers, self.cfg.latent)
            c = state[:, start + n : start + 2 * n].reshape(-1, lstm.num_layers, self.cfg.latent)
            out.append((h.transpose(0, 1).contiguous(), c.transpose(0, 1).contiguous()))
            start += 2 * n
        return out

    @staticmethod
    def _pack(states: list[tuple[torch.Tensor, torch.Tensor]]) -> torch.Tensor:
        parts = []
        for h, c in states:
            parts += [h.transpose(0, 1).flatten(1), c.transpose(0, 1).flatten(1)]
        return torch.cat(parts, dim=1)

    # --- running ---------------------------------------------------------------------------------

    def forward(self, features: torch.Tensor, style: torch.Tensor, alpha: torch.Tensor,
                state: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``features (B, T, F)``, ``style (B, S)``, ``alpha (B, 1)``, ``state (B, N)`` (None: the
        learned initial state) -> ``output (B, T, n_out)`` raw units, ``state (B, N)`` after frame T.

        Every branch runs, so the returned state is complete (what streaming needs)."""
        if state is None:
            state = self.initial_state(features.shape[0])
        z = self.encoder((features - self.in_mean) / self.in_std)
        states = self._unpack(state)
        neutral, first = self.stacks[0](z, states[0])
        new_states = [first]
        weights = style.index_select(1, self.branch_columns) * alpha  # (B, branches)
        residual = torch.zeros_like(neutral)
        for k, (lstm, s) in enumerate(zip(self.stacks[1:], states[1:])):
            y, s_out = lstm(z, s)
            residual = residual + weights[:, k, None, None] * y
            new_states.append(s_out)
        return self._decode(neutral + residual, style, alpha), self._pack(new_states)

    def stylize(self, features: torch.Tensor, target: torch.Tensor, with_neutral: bool = False
                ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """Training path: ``features (B, T, F)`` from the learned initial state to one-hot target
        style indices ``target (B,)``; runs each branch only on the sequences that target it.
        ``with_neutral``: also the neutral stack's output ``(B, T, latent)`` (what a style
        adversary reads)."""
        b = features.shape[0]
        z = self.encoder((features - self.in_mean) / self.in_std)
        init = self._unpack(self.initial_state(b))
        out, _ = self.stacks[0](z, init[0])
        neutral = out
        columns = self.branch_columns.tolist()
        for k, lstm in enumerate(self.stacks[1:]):
            rows = (target == columns[k]).nonzero()[:, 0]
            if len(rows):
                h, c = init[k + 1]
                y, _ = lstm(z[rows], (h[:, rows].contiguous(), c[:, rows].contiguous()))
                out = out.index_add(0, rows, y)
        style = nn.functional.one_hot(target, len(self.cfg.styles)).to(features.dtype)
        output = self._decode(out, style, torch.ones(b, 1))
        return (output, neutral) if with_neutral else output

    def _decode(self, latent: torch.Tensor, style: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
        """Output frames of latent codes ``(B, T, latent)`` or ``(B, latent)`` (one step)."""
        condition = alpha * style + (1 - alpha) * self.neutral_onehot  # alpha = 0: neutral
        if latent.dim() == 3:
            condition = condition[:, None].expand(-1, latent.shape[1], -1)
        y = self.decoder(torch.cat([latent, condition], dim=-1)) * self.out_std + self.out_mean
        joints = self.cfg.n_joints
        d6 = orthonormal_6d(y[..., OUT_ROOT:].reshape(-1, joints, 6)).reshape(y.shape[:-1] + (6 * joints,))
        return torch.cat([y[..., :OUT_ROOT], d6], dim=-1)


class StepGraph(nn.Module):
    """One streaming step, the exported ONNX graph (see the recurrent model card).

    The same maths as :class:`StyleERD` on one frame, written for a small graph, because a streamed
    frame pays ONNX Runtime's cost per node more than its arithmetic: every stack's LSTM layer is
    one broadcast matrix product (stacks as a batch axis, performers as another), the state is read
    with one reshape and one split and written with one concat in :class:`StyleERD`'s flat layout,
    and the gate columns are reordered (i, f, o, g) so that one sigmoid and one tanh cover them.
    79 nodes after ORT's optimisation where the per-stack graph had 114. Needs stacks of one depth.
    """

    def __init__(self, model: StyleERD) -> None:
        super().__init__()
        self.model = model
        depths = {lstm.num_layers for lstm in model.stacks}
        if len(depths) != 1:
            raise ValueError(f"the step graph needs LSTM stacks of one depth, got {sorted(depths)} layers "
                             "(ErdConfig neutral_layers and style_layers)")
        self.layers, self.hidden, self.stacks = depths.pop(), model.cfg.latent, len(model.stacks)
        h = self.hidden
        order = torch.cat([torch.arange(0, 2 * h), torch.arange(3 * h, 4 * h), torch.arange(2 * h, 3 * h)])

        def stacked(name: str) -> torch.Tensor:  # (stacks, 4 h, ...) in i, f, o, g order
            return torch.stack([getattr(m, name) for m in model.stacks]).detach()[:, order]

        for layer in range(self.layers):
            w_ih, w_hh = stacked(f"weight_ih_l{layer}"), stacked(f"weight_hh_l{layer}")
            bias = stacked(f"bias_ih_l{layer}") + stacked(f"bias_hh_l{layer}")
            if layer == 0:  # every stack reads the latent code: one product for all of them
                self.register_buffer("w_in0", w_ih.permute(2, 0, 1).flatten(1).contiguous(), persistent=False)
                self.register_buffer("bias0", bias.flatten(), persistent=False)
            else:  # each stack reads its own layer below
                self.register_buffer(f"w_in{layer}", w_ih.transpose(1, 2).contiguous(), persistent=False)
                self.register_buffer(f"bias{layer}", bias[:, None], persistent=False)
            self.register_buffer(f"w_rec{layer}", w_hh.transpose(1, 2).contiguous(), persistent=False)

    def forward(self, features: torch.Tensor, style: torch.Tensor, alpha: torch.Tensor,
                state: torch.Tensor, reset: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        m, h, layers = self.model, self.hidden, self.layers
        # where, not a blend: a reset must also clear a state holding garbage (NaN)
        state = torch.where(reset > 0.5, m.initial_state(1), state)
        # per stack: h of every layer, then c of every layer; each (B, stacks, 1, hidden)
        parts = state.reshape(-1, self.stacks, 2 * layers, h).split(1, dim=2)
        z = m.encoder((features - m.in_mean) / m.in_std)  # (B, latent)
        x = (z @ self.w_in0 + self.bias0).reshape(-1, self.stacks, 1, 4 * h)
        hs, cs = [], []
        for layer in range(layers):
            if layer:
                x = hs[-1] @ getattr(self, f"w_in{layer}") + getattr(self, f"bias{layer}")
            gates = x + parts[layer] @ getattr(self, f"w_rec{layer}")  # (B, stacks, 1, 4 hidden)
            i, f, o = torch.sigmoid(gates[..., :3 * h]).split(h, dim=-1)
            c = f * parts[layers + layer] + i * torch.tanh(gates[..., 3 * h:])
            hs.append(o * torch.tanh(c))
            cs.append(c)
        weights = torch.cat([torch.ones_like(alpha), style.index_select(1, m.branch_columns) * alpha], dim=1)
        latent = (weights[:, :, None, None] * hs[-1]).sum(1).flatten(1)  # neutral + weighted residuals
        return m._decode(latent, style, alpha), torch.cat(hs + cs, dim=2).flatten(1)


# --- critics (training only) -----------------------------------------------------------------------


def _conv(a: int, b: int, kernel: int) -> nn.Conv1d:
    return nn.Conv1d(a, b, kernel, padding=kernel // 2, padding_mode="replicate")


class FTAttDiscriminator(nn.Module):
    """The FT-Att discriminator: temporal convolutions give a feature map ``m (C', T')``; an MLP of
    the style and content labels gives a feature attention ``w_f (C')`` and a temporal attention
    ``w_t (T')``; the score is ``sum(m * outer(w_f, w_t))``. Input: normalised joint positions and
    velocities ``(B, T, channels)`` of ``frames`` frames."""

    def __init__(self, channels: int, n_styles: int, n_contents: int, frames: int,
                 widths: tuple[int, ...] = (128, 96, 64), feature_dim: int = 16) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for a, b in zip((channels, *widths[:-1]), widths):
            layers += [_conv(a, b, 3), nn.LeakyReLU(0.2)]
        self.features = nn.Sequential(*layers, _conv(widths[-1], feature_dim, 3))
        self.attention = nn.Sequential(
            nn.Linear(n_styles + n_contents, 64), nn.LeakyReLU(0.2),
            nn.Linear(64, 64), nn.LeakyReLU(0.2),
        )
        self.feature_attention = nn.Linear(64, feature_dim)
        self.temporal_attention = nn.Linear(64, frames)

    def forward(self, x: torch.Tensor, style: torch.Tensor, content: torch.Tensor) -> torch.Tensor:
        """``x (B, T, channels)``, one-hot ``style (B, S)`` and ``content (B, C)`` -> scores ``(B,)``."""
        m = self.features(x.transpose(1, 2))  # (B, C', T')
        a = self.attention(torch.cat([style, content], dim=-1))
        w = self.feature_attention(a)[:, :, None] * self.temporal_attention(a)[:, None, :]
        return (m * w).sum(dim=(1, 2))


class _Reverse(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor, scale: float) -> torch.Tensor:
        ctx.scale = scale
        return x.view_as(x)

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        return -ctx.scale * grad, None


def reverse(x: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
    """The identity forwards, the gradient times ``-scale`` backwards: a critic read through it
    learns to recover what it reads while what feeds it learns to hide that."""
    return _Reverse.apply(x, scale)


class StyleAdversary(nn.Module):
    """A style classifier on the neutral stack's output, behind a gradient reversal: it learns to
    tell the input's style from that output while the generator learns to leave none there, so
    that what the style branches add is the only style. Without instance normalisation: a clip's
    statistics over time are where its style shows."""

    def __init__(self, latent: int, n_styles: int, width: int = 64) -> None:
        super().__init__()
        self.features = nn.Sequential(_conv(latent, width, 5), nn.LeakyReLU(0.2), _conv(width, width, 5),
                                      nn.LeakyReLU(0.2))
        self.head = nn.Linear(width, n_styles)

    def forward(self, neutral: torch.Tensor, reversal: float = 1.0) -> torch.Tensor:
        """``neutral (B, T, latent)`` -> style logits ``(B, styles)``; the gradient to ``neutral``
        reversed and scaled by ``reversal`` (the adversary itself learns at its own rate)."""
        h = self.features(reverse(neutral, reversal).transpose(1, 2))
        return self.head(h.mean(dim=-1))


class ContentNet(nn.Module):
    """Content classifier whose convolution features serve as the perceptual loss. Instance
    normalisation after every convolution removes per-clip feature statistics, which carry much of
    the style, so the features describe what is done more than how."""

    def __init__(self, channels: int, n_contents: int, widths: tuple[int, ...] = (128, 96, 64)) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(
            nn.Sequential(_conv(a, b, 5), nn.InstanceNorm1d(b), nn.LeakyReLU(0.2))
            for a, b in zip((channels, *widths[:-1]), widths)
        )
        self.head = _conv(widths[-1], n_contents, 5)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """``x (B, T, channels)`` normalised -> ``logits (B, contents)``, per-block feature maps."""
        h = x.transpose(1, 2)
        maps = []
        for block in self.blocks:
            h = block(h)
            maps.append(h)
        return self.head(h).mean(dim=-1), maps
