"""The *reference* Style-ERD generator at its original architecture and default size, for timing.

This is an independent re-implementation (random, seeded weights, nothing copied) of the
generator in Tao et al. 2022, "Style-ERD: Responsive and Coherent Online Motion Style Transfer",
as its reference code builds it (github tianxintao/Online-Motion-Style-Transfer). It exists only
so the bench can time one streaming step of the reference architecture beside our own ONNX
pipeline. It is never trained and must never be used to stylize anything: its weights are noise.

Where the structure and sizes come from (paths in that repository; line numbers at the commits
named):

* ``model.py`` @ 8f9d57a6, ``Encoder`` (l. 23-38): ``encoder_layer_num`` Linear+ReLU layers, each
  ``w -> w // 4 * 2``, then a Linear to ``latent_dim``; input is the concatenation rotation |
  position | velocity | contact | content one-hot | input-style one-hot.
* ``model.py`` ``ResidualAdapter`` (l. 41-89): a neutral LSTM stack (``neutral_layer_num``
  layers, width ``latent_dim``) plus one residual LSTM stack per style (``style_layer_num``
  layers); learned initial ``(h, c)`` per content (neutral stack) and per style (residual stacks).
  At test time (l. 71-81, used by ``test.py`` with ``test_time=True``) only the target style's
  stack runs and is added to the neutral output (neutral target: the neutral stack alone); in
  training (l. 82-89) all residual stacks run and are summed weighted by the style vector.
* ``model.py`` ``Decoder`` (l. 92-131): input latent | style one-hot (the style part is zeroed in
  ``forward``, l. 110), ``decoder_layer_num - 1`` Linear+ReLU layers each
  ``w -> int(w * 1.5 // 2 * 2)``, then linear heads for rotation (quaternions, normalised per
  joint, l. 114-118), position (absent with ``--no_pos``) and velocity (absent with ``--no_vel``).
* ``train.py`` @ a6d2c74e, ``ArgParserTrain`` (l. 32-33, 50-58): ``style_num=7``,
  ``content_num=5``, ``no_pos=False``, ``no_vel=False``, ``encoder_layer_num=2``,
  ``decoder_layer_num=4``, ``latent_dim=32``, ``neutral_layer_num=4``, ``style_layer_num=6``
  (``test.py`` repeats the same defaults).
* ``dataloader.py`` @ 82575e76 (l. 62-70) takes the feature sizes from the data: rotation =
  all skeleton joints x 4 (``utils/animation_data.py``, ``get_joint_rotation``), position and
  velocity = (chosen joints - 1) x 3 (``get_joint_position``/``get_joint_velocity``), contact 4.
  The skeleton file (``global_info/skeleton_CMU.yml``, read by ``utils/load_skeleton.py``) is not in
  the stored snapshot; the same-named file of the Xia-data pipeline it derives from
  (DeepMotionEditing/deep-motion-editing ``style_transfer/global_info/skeleton_CMU.yml``) has 31
  joints (``parents``) and 21 chosen joints, so rotation 124, position 60, velocity 60, and the
  encoder input 124 + 60 + 60 + 4 + 5 + 7 = 260.

Resulting default generator: encoder 260 -> 130 -> 64 -> 32; neutral LSTM 4 x 32; 7 residual
LSTMs 6 x 32; decoder 39 -> 58 -> 86 -> 128 -> heads 124 | 60 | 60 (output 244 per frame);
486,976 parameters (see ``test/test_reference_erd.py`` for the arithmetic).

Streaming: every part is per frame except the LSTMs, which are causal, so running frame by frame
with the ``(h, c)`` carried between calls gives exactly what the reference computes over a whole
clip at once. No window of past frames is needed (with the default ``no_vel=False`` velocity is a
per-frame head), so :class:`ReferenceStream` keeps no frame buffer.

Not reproduced: the ``--no_pos`` variant that the README's commands use (position from forward
kinematics on the 31-joint skeleton instead of the position head; 7,740 parameters fewer, plus
the FK cost), the discriminator and the content classifier (training only).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import torch
from torch import nn

State = list[tuple[torch.Tensor, torch.Tensor]]
# torch threads the references are timed on: their code runs on a CPU with torch's default threads
# (2 cores here); bench recurrent and bench stgcn both use it
REFERENCE_THREADS = 2


@dataclass(frozen=True)
class ReferenceSizes:
    """The reference's default sizes (``train.py`` arguments and the Xia/CMU feature sizes)."""

    rotation: int = 124  # 31 joints x quaternion
    position: int = 60  # 20 non-root chosen joints x 3
    velocity: int = 60
    contact: int = 4
    contents: int = 5
    styles: int = 7
    latent: int = 32
    encoder_layers: int = 2
    decoder_layers: int = 4
    neutral_layers: int = 4
    style_layers: int = 6

    @property
    def n_in(self) -> int:
        """Per-frame input width: rotation | position | velocity | contact | content | style."""
        return (self.rotation + self.position + self.velocity + self.contact + self.contents
                + self.styles)

    @property
    def n_out(self) -> int:
        """Per-frame output width: rotation | position | velocity."""
        return self.rotation + self.position + self.velocity

    @property
    def encoder_widths(self) -> tuple[int, ...]:
        """Hidden widths of the encoder: each layer keeps ``w // 4 * 2`` of its input."""
        widths, w = [], self.n_in
        for _ in range(self.encoder_layers):
            w = w // 4 * 2
            widths.append(w)
        return tuple(widths)

    @property
    def decoder_widths(self) -> tuple[int, ...]:
        """Hidden widths of the decoder: each layer grows by 1.5, rounded down to an even number."""
        widths, w = [], self.latent + self.styles
        for _ in range(self.decoder_layers - 1):
            w = int(w * 1.5 // 2 * 2)
            widths.append(w)
        return tuple(widths)


def _relu_stack(sizes: list[int]) -> list[nn.Module]:
    layers: list[nn.Module] = []
    for a, b in pairwise(sizes):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return layers


class ReferenceERD(nn.Module):
    """The reference generator: encoder MLP, neutral + per-style residual LSTMs, decoder MLP.

    Random weights from ``seed`` (the global RNG is left untouched); gradients are off, it is a
    timing stand-in only.
    """

    def __init__(self, sizes: ReferenceSizes | None = None, seed: int = 0) -> None:
        super().__init__()
        s = self.sizes = sizes or ReferenceSizes()
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            enc = [s.n_in, *s.encoder_widths]
            self.encoder = nn.Sequential(*_relu_stack(enc), nn.Linear(enc[-1], s.latent))
            self.neutral = nn.LSTM(s.latent, s.latent, s.neutral_layers, batch_first=True)
            self.residual = nn.ModuleList(
                nn.LSTM(s.latent, s.latent, s.style_layers, batch_first=True)
                for _ in range(s.styles))
            # learned initial (h, c): per content for the neutral stack, per style for the others
            # (zeros in the reference before training; small noise here so they matter)
            neutral0 = (s.neutral_layers, s.contents, s.latent)
            residual0 = (s.style_layers, s.styles, s.latent)
            self.neutral_h0 = nn.Parameter(0.1 * torch.randn(neutral0))
            self.neutral_c0 = nn.Parameter(0.1 * torch.randn(neutral0))
            self.residual_h0 = nn.Parameter(0.1 * torch.randn(residual0))
            self.residual_c0 = nn.Parameter(0.1 * torch.randn(residual0))
            dec = [s.latent + s.styles, *s.decoder_widths]
            self.decoder = nn.Sequential(*_relu_stack(dec))
            self.rotation_head = nn.Linear(dec[-1], s.rotation)
            self.position_head = nn.Linear(dec[-1], s.position)
            self.velocity_head = nn.Linear(dec[-1], s.velocity)
        self.requires_grad_(False)
        self.eval()

    def initial_state(self, content: int, branches: tuple[int, ...], batch: int = 1) -> State:
        """Learned initial ``(h, c)`` for the neutral stack, then for each residual stack used."""
        def expand(p: torch.Tensor, i: int) -> torch.Tensor:
            return p[:, i : i + 1, :].expand(-1, batch, -1).contiguous()

        state = [(expand(self.neutral_h0, content), expand(self.neutral_c0, content))]
        state += [(expand(self.residual_h0, i), expand(self.residual_c0, i)) for i in branches]
        return state

    def forward(self, x: torch.Tensor, state: State, branches: tuple[int, ...],
                weights: tuple[float, ...] | None = None) -> tuple[torch.Tensor, State]:
        """Run frames ``x`` ``(B, T, n_in)`` from ``state``; returns ``((B, T, n_out), state)``.

        ``branches`` are the residual stacks run (test time: the target style only, none for a
        neutral target); ``weights`` scale them (default 1, the test-time path).
        """
        s = self.sizes
        latent = self.encoder(x)
        core, neutral_state = self.neutral(latent, state[0])
        new_state = [neutral_state]
        for k, i in enumerate(branches):
            r, r_state = self.residual[i](latent, state[k + 1])
            core = core + (r if weights is None else weights[k] * r)
            new_state.append(r_state)
        # the reference concatenates the style one-hot, then zeroes it before the decoder
        style = core.new_zeros(core.shape[:-1] + (s.styles,))
        h = self.decoder(torch.cat((core, style), dim=-1))
        rot = self.rotation_head(h)
        quats = rot.unflatten(-1, (-1, 4))
        rot = (quats / quats.norm(dim=-1, keepdim=True)).flatten(-2)
        out = torch.cat((rot, self.position_head(h), self.velocity_head(h)), dim=-1)
        return out, new_state


class ReferenceStream:
    """One online performer on a :class:`ReferenceERD`: one frame in, one frame out, the LSTM
    state carried between calls (no frame window: the reference needs none).

    ``style=None`` is a neutral target (neutral stack only). ``mix=True`` runs all residual
    stacks weighted by the target's one-hot, as the reference's training path (and style mixing)
    does; the default is its test-time path, one residual stack.
    """

    def __init__(self, model: ReferenceERD, content: int = 0, style: int | None = 4,
                 mix: bool = False) -> None:
        self.model = model
        self.content = content
        n_styles = model.sizes.styles
        if mix:
            self.branches = tuple(range(n_styles))
            self.weights: tuple[float, ...] | None = tuple(
                1.0 if i == style else 0.0 for i in range(n_styles))
        else:
            self.branches = () if style is None else (style,)
            self.weights = None
        self.reset()

    def reset(self) -> None:
        """Back to the learned initial state (a new clip)."""
        self.state = self.model.initial_state(self.content, self.branches)

    def step(self, frame: torch.Tensor) -> torch.Tensor:
        """Stylize one frame ``(n_in,)`` (or ``(1, n_in)``); returns ``(n_out,)``."""
        x = frame.reshape(1, 1, -1)
        out, self.state = self.model(x, self.state, self.branches, self.weights)
        return out[0, 0]


def reference_step_times(threads: int = REFERENCE_THREADS, calls: int = 2000,
                         warmup: int = 100) -> tuple[float, float]:
    """``(p50, p99)`` microseconds of one :meth:`ReferenceStream.step` (batch 1, default size,
    test-time path) under ``torch.inference_mode()`` with ``threads`` torch threads; the previous
    thread count is restored afterwards."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        stream = ReferenceStream(ReferenceERD(seed=0))
        gen = torch.Generator().manual_seed(1)
        frame = torch.randn(stream.model.sizes.n_in, generator=gen)
        times = np.empty(calls, dtype=np.float64)
        with torch.inference_mode():
            for _ in range(warmup):
                stream.step(frame)
            for k in range(calls):
                t0 = time.perf_counter_ns()
                stream.step(frame)
                times[k] = time.perf_counter_ns() - t0
    finally:
        torch.set_num_threads(previous)
    p50, p99 = np.percentile(times, [50, 99]) / 1e3
    return float(p50), float(p99)
