"""The judges: small networks that classify a clip's style or content from its features.

Two panels, built differently so that one cannot share the other's blind spots: the first
(:class:`Judge`, a temporal CNN on root motion, joint positions, velocities and foot contacts) is
what training runs may be compared and selected with; the second (style: :class:`RecurrentJudge`, a
bidirectional GRU; content: a wider CNN; both on root motion, joint positions and velocities,
another seed, no epoch selection) only ever reports. A third style judge (a :class:`Judge` on root
motion and joint velocities only) may guide choices beside the first: pseudo-pair targets must
satisfy both.

They are evaluation instruments, trained on real clips only; a stylizer must never be trained
against them (it would learn to fool the judge, and the judge would stop measuring anything).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class _Normalised(nn.Module):
    """What every judge shares: the train-set feature mean and std as buffers (so the exported
    graph takes raw features) and the feature columns it looks at (derived from the card's
    ``inputs``, not saved)."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, columns: np.ndarray | None) -> None:
        super().__init__()
        columns = np.arange(len(mean)) if columns is None else np.asarray(columns)
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.register_buffer("columns", torch.as_tensor(columns, dtype=torch.int64), persistent=False)

    def inputs(self, features: torch.Tensor) -> torch.Tensor:
        """Raw ``(B, T, F)`` -> normalised ``(B, T, columns)``."""
        return ((features - self.mean) / self.std).index_select(-1, self.columns)


class Judge(_Normalised):
    """Raw ``encode()`` features ``(B, T, F)`` -> ``logits (B, classes)``, ``embedding (B, E)``.

    ``columns`` picks the feature blocks the judge sees (see ``training.judges.Config.inputs``).
    The train-set feature mean and std are buffers of the network, so the exported ONNX graph
    takes raw features. Four Conv1d layers (kernel 5, two with stride 2, one dilated) see 33
    frames (1.1 s at 30 fps) each; averaging over time makes the embedding independent of clip
    length.
    The convolutions pad by repeating edge frames, so any clip of one frame or more is accepted
    (short clips are padded the same way); clips under a second carry little style, though.
    """

    def __init__(
        self,
        mean: np.ndarray,
        std: np.ndarray,
        n_classes: int,
        width: int = 64,
        embedding: int = 64,
        dropout: float = 0.2,
        columns: np.ndarray | None = None,
    ) -> None:
        super().__init__(mean, std, columns)
        n_features = len(self.columns)
        act = nn.LeakyReLU(0.2)
        self.encoder = nn.Sequential(
            nn.Dropout(dropout),
            nn.Conv1d(n_features, width, 5, padding=2, padding_mode="replicate"),
            act,
            nn.Conv1d(width, width, 5, stride=2, padding=2, padding_mode="replicate"),
            act,
            nn.Conv1d(width, width, 5, dilation=2, padding=4, padding_mode="replicate"),
            act,
            nn.Conv1d(width, embedding, 5, stride=2, padding=2, padding_mode="replicate"),
            act,
        )
        self.head = nn.Sequential(nn.Dropout(dropout), nn.Linear(embedding, n_classes))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        embedding = self.encoder(self.inputs(features).transpose(1, 2)).mean(dim=-1)
        return self.head(embedding), embedding


class RecurrentJudge(_Normalised):
    """The second panel's judge: raw ``encode()`` features ``(B, T, F)`` -> ``logits (B, classes)``,
    ``embedding (B, E)``. A linear projection, a 2-layer bidirectional GRU, then mean and max over
    time (any clip length) projected to the embedding. Same interface as :class:`Judge`."""

    def __init__(
        self,
        mean: np.ndarray,
        std: np.ndarray,
        n_classes: int,
        width: int = 64,
        embedding: int = 64,
        dropout: float = 0.2,
        columns: np.ndarray | None = None,
    ) -> None:
        super().__init__(mean, std, columns)
        self.project = nn.Sequential(nn.Dropout(dropout), nn.Linear(len(self.columns), width), nn.Tanh())
        self.gru = nn.GRU(width, width, num_layers=2, batch_first=True, bidirectional=True)
        self.pool = nn.Sequential(nn.Linear(4 * width, embedding), nn.Tanh())
        self.head = nn.Sequential(nn.Dropout(dropout), nn.Linear(embedding, n_classes))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, _ = self.gru(self.project(self.inputs(features)))
        embedding = self.pool(torch.cat([h.mean(dim=1), h.amax(dim=1)], dim=-1))
        return self.head(embedding), embedding


ARCHITECTURES = {"cnn": Judge, "gru": RecurrentJudge}
