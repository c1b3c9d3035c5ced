"""The *reference* ST-GCN stylizer's generator at its original architecture and default size, for timing.

This is an independent re-implementation (random, seeded weights, nothing copied) of the generator
in Park et al. 2021, "Diverse Motion Stylization for Multiple Style Domains via Spatial-Temporal
Graph-Based Generative Model", as its reference code builds it (github
soomean/Diverse-Motion-Stylization). It exists only so the windowed bench can time one forward
pass of the reference architecture beside our own ONNX pipeline. It is never trained and must
never be used to stylize anything: its weights are noise.

Where the structure and sizes come from (paths in that repository, all at commit d982960f except
``test.py`` at df557923):

* ``options/base_options.py`` (l. 30-39): ``input_nc = output_nc = 7``, ``ngf = 64``,
  ``style_dim = 64``, ``ng_blk = 2``, ``ng_btn = 0`` (also ``latent_dim = 16``,
  ``hidden_dim = 512`` for the mapping network); ``options/test_options.py`` (l. 16):
  ``clip_size = [64, 21]`` (the style encoder's window; the generator takes any length).
* ``model/motion_graph_gan_model.py`` (l. 19) builds the generator with ``define_G``
  (``model/st_networks.py`` l. 43); ``init_weights`` (l. 14-26): Kaiming-normal (fan in, ReLU)
  weights and zero biases for every Conv2d and Linear.
* ``model/st_networks.py`` ``Generator`` (l. 383-400): 1x1 conv 7 -> 64, an encoder, a decoder
  given the style code, 1x1 conv 64 -> 7. ``Encoder`` (l. 309-342): ``ng_blk`` residual blocks
  ``64 * 2**i -> 64 * 2**(i+1)`` with instance norm and down-sampling (no bottleneck blocks at
  ``ng_btn = 0``); ``Decoder`` (l. 345-380): the mirror image, ``256 -> 128 -> 64``, AdaIN and
  up-sampling.
* ``ST_ResBlk`` (l. 183-235): residual = affine instance norm, leaky ReLU 0.2, ST conv
  ``c_in -> c_in`` on the fine graph that pools joints and frames, affine instance norm, leaky
  ReLU, ST conv ``c_in -> c_out`` on the coarse graph; shortcut = bias-free 1x1 projection, then the
  same pooling; the sum divided by sqrt 2.
* ``ST_AdaINResBlk`` (l. 251-303) with ``AdaIN`` (l. 238-248: instance norm without affine, a
  Linear ``style_dim -> 2 c`` giving ``(1 + gamma) * x + beta``): AdaIN, leaky ReLU, ST conv
  ``c_in -> c_out`` on the coarse graph that unpools joints and frames, AdaIN, leaky ReLU, ST conv
  ``c_out -> c_out`` on the fine graph; shortcut = unpool first, then the bias-free 1x1
  projection; sum / sqrt 2.
* ``ST_Conv`` / ``ST_ConvTranspose`` (l. 76-136): graph conv (spatial kernel 3), optional
  pool/unpool, ReLU, temporal conv ``(3, 1)`` with padding 1, stride 1, biases on.
  ``model/gcn.py`` ``GraphConv`` (l. 6-30): a 1x1 conv to ``3 c_out`` channels with bias, then a
  sum over the 3 partitions and the joints, ``x[k, v] * A[k, v, w]``.
* Pooling (l. 142-177): joints by a matrix product with ``M``; frames by average pooling of 2
  (floor) and, going up, bilinear interpolation x 2 with ``align_corners=True``.
* ``data/graph.py`` (l. 56-80): the 21-joint skeleton (centre 0), a 10-node body-part graph
  (centre 4) and a 5-node one (centre 2); adjacency (l. 92-161) with ``max_hop = 1``: self and
  neighbours, each column divided by its sum, split into 3 partitions by the ``spatial`` strategy
  (self; neighbours not farther from the centre than the joint they feed; neighbours farther).
  The distance to the centre is itself taken from the 1-hop distance table, so every joint two or
  more hops from the centre counts as equally far (infinite); reproduced as is.
* ``data/skeleton_graph.py`` (l. 5-22, 40-80): the joint clusters 21 -> 10 -> 5; pooling averages
  a cluster's joints, unpooling copies the cluster's value back onto each of them.
  ``processor.py`` ``set_adjacency`` (l. 28-57) hands block ``i`` of the encoder the graphs of
  levels ``i - 1`` and ``i`` and the decoder the reverse.
* ``preprocess/export_dataset.py`` (l. 11-24, 108-150): 21 of the BVH's 31 joints, per joint
  position (3) | global rotation quaternion (4) | root trajectory (4); the generator sees the
  first 7 (``data/data_loader.py`` l. 168). The last frame is dropped (l. 136-137).

How ``test.py`` (l. 51-61) runs it: the source is the whole of ``output/walking_neutral.bvh``
(327 frames at 24 fps, ``downsample=1``: 326 frames after the dropped one), batch 1; the style
code comes either from the style encoder on the first 64 frames of ``output/jumping_old.bvh`` or
from the mapping network on 16 Gaussian numbers (``processor.py`` ``Processor.test``,
l. 173-197), then one generator pass under ``torch.no_grad()``. Time halves twice and doubles
twice, so the output has ``4 * (T // 4)`` frames: 324 for the 326-frame source (the repository's
``output/output_*_fs.bvh`` have 324 frames).

Resulting default generator: 7 -> 64 (1x1) -> [64 -> 128, 21 -> 10 joints, T -> T/2]
-> [128 -> 256, 10 -> 5 joints, T/2 -> T/4] -> [256 -> 128, 5 -> 10 joints] -> [128 -> 64, 10 -> 21
joints] -> 7 (1x1); 961,095 parameters (see ``test/test_reference_stgcn.py`` for the arithmetic).

Not reproduced: the mapping network and the style encoder (the timing uses a fixed random style
code in the mapping network's tanh range; the mapping network is a small MLP, the style encoder
a 64-frame run of an encoder like the generator's), the discriminator, the data normalisation
(``Xmean``/``Xstd``), and the foot-contact clean-up and BVH writing after the pass
(``utils/logger.py``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion_style_ros.models.reference_erd import REFERENCE_THREADS
from motion_style_ros.models.stgcn import AdaIN  # the same block: instance norm, (1 + gamma) x + beta

SLOPE = 0.2  # the blocks' leaky ReLU

# The three graph levels as parent lists (-1: the centre the spatial partitions are measured
# from). Level 0: the 21 selected joints (root, left leg 1-4, right leg 5-8, spine 9-12, left arm
# 13-16, right arm 17-20); level 1: ten body parts; level 2: five limbs and the trunk.
PARENTS = (
    (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 10, 13, 14, 15, 10, 17, 18, 19),
    (4, 0, 4, 2, -1, 4, 5, 6, 5, 8),
    (2, 2, -1, 2, 2),
)
# The joints of level k that make up each node of level k + 1.
CLUSTERS = (
    ((1, 2), (3, 4), (5, 6), (7, 8), (0, 9), (10, 11, 12), (13, 14), (15, 16), (17, 18), (19, 20)),
    ((0, 1), (2, 3), (4, 5), (6, 7), (8, 9)),
)


@dataclass(frozen=True)
class ReferenceStgcnSizes:
    """The reference's default sizes (``options/base_options.py``) and its test clip."""

    channels: int = 7  # per joint in and out: position (3) | rotation quaternion (4)
    width: int = 64  # ngf
    blocks: int = 2  # ng_blk (down and up)
    style_dim: int = 64
    joints: int = 21
    partitions: int = 3  # spatial strategy at max_hop 1
    temporal_kernel: int = 3
    frames: int = 326  # output/walking_neutral.bvh: 327 frames, the last dropped

    @property
    def widths(self) -> tuple[int, ...]:
        """Channels after the input conv and after each encoder block: 64, 128, 256."""
        return tuple(self.width * 2**i for i in range(self.blocks + 1))

    @property
    def output_frames(self) -> int:
        """Frames out: time halves ``blocks`` times (rounding down), then doubles as often."""
        return self.frames // 2**self.blocks * 2**self.blocks


def spatial_partitions(parents: tuple[int, ...]) -> np.ndarray:
    """``(3, V, V)`` adjacency of one graph level, entry ``[k, v, w]`` the weight of joint ``v``
    in joint ``w``'s sum: self, neighbours no farther from the centre, neighbours farther. Each
    column of the 1-hop adjacency (with self) is divided by its sum first; distances to the centre
    go only to one hop (beyond counts as infinitely far), as the reference computes them."""
    n = len(parents)
    link = np.eye(n, dtype=bool)
    for child, parent in enumerate(parents):
        if parent >= 0:
            link[child, parent] = link[parent, child] = True
    weight = link / link.sum(axis=0, keepdims=True)
    centre = parents.index(-1)
    reach = np.full(n, np.inf)
    reach[link[centre]] = 1.0
    reach[centre] = 0.0
    neighbour = link & ~np.eye(n, dtype=bool)
    farther = neighbour & (reach[:, None] > reach[None, :])
    return np.stack([np.diag(np.diag(weight)),
                     np.where(neighbour & ~farther, weight, 0.0),
                     np.where(farther, weight, 0.0)]).astype(np.float32)


def pool_matrix(clusters: tuple[tuple[int, ...], ...], n_fine: int) -> np.ndarray:
    """``(V_fine, V_coarse)``: each coarse node the mean of its cluster's joints."""
    m = np.zeros((n_fine, len(clusters)), np.float32)
    for k, members in enumerate(clusters):
        m[list(members), k] = 1.0 / len(members)
    return m


def unpool_matrix(clusters: tuple[tuple[int, ...], ...], n_fine: int) -> np.ndarray:
    """``(V_coarse, V_fine)``: each joint takes its cluster's value."""
    m = np.zeros((len(clusters), n_fine), np.float32)
    for k, members in enumerate(clusters):
        m[k, list(members)] = 1.0
    return m


def _joints(x: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """``(N, C, T, V) x (V, W) -> (N, C, T, W)``: pool or unpool joints."""
    return torch.einsum("nctv,vw->nctw", x, matrix).contiguous()


class _GraphConv(nn.Module):
    """One 1x1 conv per partition (as one conv to ``3 c_out`` channels), summed over each joint's
    partition neighbours."""

    def __init__(self, c_in: int, c_out: int, partitions: int) -> None:
        super().__init__()
        self.partitions = partitions
        self.conv = nn.Conv2d(c_in, partitions * c_out, 1)

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        y = self.conv(x)
        y = y.unflatten(1, (self.partitions, -1))
        return torch.einsum("nkctv,kvw->nctw", y, a).contiguous()


class _STConv(nn.Module):
    """Graph conv, optional joint/frame pooling (``"down"``) or unpooling (``"up"``), ReLU,
    temporal conv."""

    def __init__(self, c_in: int, c_out: int, sizes: ReferenceStgcnSizes, resample: str | None = None) -> None:
        super().__init__()
        self.resample = resample
        self.graph = _GraphConv(c_in, c_out, sizes.partitions)
        k = sizes.temporal_kernel
        self.time = nn.Conv2d(c_out, c_out, (k, 1), padding=((k - 1) // 2, 0))

    def forward(self, x: torch.Tensor, a: torch.Tensor, m: torch.Tensor | None = None) -> torch.Tensor:
        x = self.graph(x, a)
        if self.resample == "down":
            x = F.avg_pool2d(_joints(x, m), (2, 1))
        elif self.resample == "up":
            x = _upsample_time(_joints(x, m))
        return self.time(F.relu(x, inplace=True))


def _upsample_time(x: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, scale_factor=(2.0, 1.0), mode="bilinear", align_corners=True)


class _DownBlock(nn.Module):
    """Encoder residual block: graph level ``k`` -> ``k + 1``, frames halved."""

    def __init__(self, c_in: int, c_out: int, level: int, sizes: ReferenceStgcnSizes) -> None:
        super().__init__()
        self.level = level
        self.norm1 = nn.InstanceNorm2d(c_in, affine=True)
        self.conv1 = _STConv(c_in, c_in, sizes, "down")
        self.norm2 = nn.InstanceNorm2d(c_in, affine=True)
        self.conv2 = _STConv(c_in, c_out, sizes)
        self.project = nn.Conv2d(c_in, c_out, 1, bias=False)

    def forward(self, x: torch.Tensor, graphs: _Graphs) -> torch.Tensor:
        k = self.level
        a_fine, a_coarse, pool = graphs.a(k), graphs.a(k + 1), graphs.pool(k)
        h = self.conv1(F.leaky_relu(self.norm1(x), SLOPE), a_fine, pool)
        h = self.conv2(F.leaky_relu(self.norm2(h), SLOPE), a_coarse)
        shortcut = F.avg_pool2d(_joints(self.project(x), pool), (2, 1))
        return (shortcut + h) / math.sqrt(2)


class _UpBlock(nn.Module):
    """Decoder residual block: graph level ``k + 1`` -> ``k``, frames doubled, AdaIN."""

    def __init__(self, c_in: int, c_out: int, level: int, sizes: ReferenceStgcnSizes) -> None:
        super().__init__()
        self.level = level
        self.norm1 = AdaIN(sizes.style_dim, c_in)
        self.conv1 = _STConv(c_in, c_out, sizes, "up")
        self.norm2 = AdaIN(sizes.style_dim, c_out)
        self.conv2 = _STConv(c_out, c_out, sizes)
        self.project = nn.Conv2d(c_in, c_out, 1, bias=False)

    def forward(self, x: torch.Tensor, s: torch.Tensor, graphs: _Graphs) -> torch.Tensor:
        k = self.level
        a_coarse, a_fine, unpool = graphs.a(k + 1), graphs.a(k), graphs.unpool(k)
        h = self.conv1(F.leaky_relu(self.norm1(x, s), SLOPE), a_coarse, unpool)
        h = self.conv2(F.leaky_relu(self.norm2(h, s), SLOPE), a_fine)
        shortcut = self.project(_upsample_time(_joints(x, unpool)))
        return (shortcut + h) / math.sqrt(2)


class _Graphs(nn.Module):
    """Partitioned adjacency of each level and the (un)pooling matrices between levels, as buffers
    (the reference passes them to every call; they are not parameters)."""

    def __init__(self, levels: int) -> None:
        super().__init__()
        for k in range(levels + 1):
            self.register_buffer(f"a{k}", torch.from_numpy(spatial_partitions(PARENTS[k])))
        for k in range(levels):
            n_fine = len(PARENTS[k])
            self.register_buffer(f"pool{k}", torch.from_numpy(pool_matrix(CLUSTERS[k], n_fine)))
            self.register_buffer(f"unpool{k}", torch.from_numpy(unpool_matrix(CLUSTERS[k], n_fine)))

    def a(self, k: int) -> torch.Tensor:
        return getattr(self, f"a{k}")

    def pool(self, k: int) -> torch.Tensor:
        return getattr(self, f"pool{k}")

    def unpool(self, k: int) -> torch.Tensor:
        return getattr(self, f"unpool{k}")


class ReferenceSTGCN(nn.Module):
    """The reference generator: ``(x (N, 7, T, 21), style code (N, 64))`` ->
    ``(N, 7, 4 * (T // 4), 21)``.

    Random weights from ``seed`` with the reference's initialisation (the global RNG is left
    untouched); gradients are off, it is a timing stand-in only.
    """

    def __init__(self, sizes: ReferenceStgcnSizes | None = None, seed: int = 0) -> None:
        super().__init__()
        s = self.sizes = sizes or ReferenceStgcnSizes()
        if s.blocks > len(CLUSTERS):
            raise ValueError(f"the reference's graph has {len(CLUSTERS)} pooling levels, not {s.blocks}")
        w = s.widths
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.graphs = _Graphs(s.blocks)
            self.first = nn.Conv2d(s.channels, w[0], 1)
            self.down = nn.ModuleList(_DownBlock(w[k], w[k + 1], k, s) for k in range(s.blocks))
            self.up = nn.ModuleList(_UpBlock(w[k + 1], w[k], k, s) for k in reversed(range(s.blocks)))
            self.last = nn.Conv2d(w[0], s.channels, 1)
            for module in self.modules():
                if isinstance(module, (nn.Conv2d, nn.Linear)):
                    nn.init.kaiming_normal_(module.weight, mode="fan_in", nonlinearity="relu")
                    if module.bias is not None:
                        nn.init.zeros_(module.bias)
        self.requires_grad_(False)
        self.eval()

    def forward(self, x: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """Stylize whole clips ``x`` with style codes ``style``."""
        h = self.first(x)
        for block in self.down:
            h = block(h, self.graphs)
        for block in self.up:
            h = block(h, style, self.graphs)
        return self.last(h)


def reference_window_times(threads: int = REFERENCE_THREADS, calls: int = 50,
                           warmup: int = 5) -> tuple[float, float, int]:
    """``(p50, p99, frames)``: milliseconds of one :class:`ReferenceSTGCN` pass on the reference's
    default test clip (batch 1, default size, a fixed random style code in place of the mapping
    network's) under ``torch.inference_mode()`` with ``threads`` torch threads, and that clip's
    frames, so a caller can compare a per-frame cost. The previous thread count is restored."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        model = ReferenceSTGCN(seed=0)
        s = model.sizes
        gen = torch.Generator().manual_seed(1)
        clip = torch.randn(1, s.channels, s.frames, s.joints, generator=gen)
        code = torch.rand(1, s.style_dim, generator=gen) * 2 - 1  # tanh range
        times = np.empty(calls, dtype=np.float64)
        with torch.inference_mode():
            for _ in range(warmup):
                model(clip, code)
            for k in range(calls):
                t0 = time.perf_counter_ns()
                model(clip, code)
                times[k] = time.perf_counter_ns() - t0
    finally:
        torch.set_num_threads(previous)
    p50, p99 = np.percentile(times, [50, 99]) / 1e6
    return float(p50), float(p99), s.frames
