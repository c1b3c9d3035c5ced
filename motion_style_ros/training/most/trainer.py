"""MoST training (Kim et al. 2024) on Bandai Namco takes: the config and the trainer's step and
validation (the loop is ``training.loop.ResumableTrainer``, the export ``training.most.export``).

Each iteration draws content windows of real train takes, a random other target style for each,
and two style windows of that style from takes of different contents (where the style has them).
The content windows are restyled like the first style window; the losses (paper section 3.6 and
its appendix, in the shared units of ``training.losses.Losses``: rotation angle, FK positions and
velocities, root block):

- **style disentanglement**: the transfer from the second style window (no gradient through it)
  must give the same motion as the one from the first;
- **physics**: the transfer's pose velocity and acceleration (and its global velocity's change)
  kept small, and feet the content window holds in contact kept still in the transfer and in the
  content cycle;
- **adversarial**: a per-style discriminator, real style windows of their style against transfers
  to it (non-saturating, lazy R1 on real windows);
- **reconstruction**: a window restyled like itself is the window;
- **cycle**: the transfer restyled like the content window is the content window, the style window
  restyled like the transfer is the style window.

The weight average of the model (encoder, modulator, generator) is exported, with every style's
mean style features over train windows for ``target_style``.

Speed: on one torch thread pinned to one core while the SAAE run held the other (2-core machine,
default config, Bandai dataset-2), 2.0 iterations/s: the shipped model made 11,990 iterations in
100 minutes. Two torch threads on a busy machine are far slower (every operation waits for the
second thread); on an idle one, take two.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.models.most import Discriminator, MoST, MostConfig, StyleFeatures
from motion_style_ros.training import hardware
from motion_style_ros.training.content import ContentConfig, content_network
from motion_style_ros.training.data import (
    FPS,
    Clips,
    Data,
    other_styles,
    style_windows,
    windows,
)
from motion_style_ros.training.loop import (
    CHECKPOINTS,
    ResumableTrainer,
    fit_for_export,
    update_average,
)
from motion_style_ros.training.losses import Losses, pose, val_scores
from motion_style_ros.training.most.export import write_model

NAME = "most"


@dataclass(frozen=True)
class Config(ContentConfig):
    """Everything that shapes a MoST run, the seed and data fields of :class:`DataConfig` and the
    content network's (:class:`ContentConfig`, trained only when ``w_content_net`` is on) first; a
    checkpoint resumes only under the same config."""

    # networks (models.most.MostConfig); the paper: dim 48, 4 heads, 2 + 1 encoder blocks, 3
    # generator blocks, 1 discriminator block, 200 frames at 60 fps
    window: int = 48
    dim: int = 48
    heads: int = 4
    enc_blocks: int = 2
    dec_blocks: int = 2
    dis_blocks: int = 1
    ff_expand: float = 1.0
    residual: bool = False  # the generator changes the input's frames (models.most.MostConfig)
    # optimisation: Adam as the paper's code (betas, weight decay); its rates (1e-5, 1e-6 over 300k
    # iterations) are far too slow for a two-hour run
    batch: int = 8
    lr: float = 2e-4  # encoder, modulator, generator
    lr_dis: float = 5e-5
    betas: tuple[float, float] = (0.9, 0.99)
    weight_decay: float = 1e-4
    ema: float = 0.999
    # loss weights (the paper's code: adversarial 1, reconstruction 3, both cycles 3,
    # disentanglement 1, velocity 1, acceleration 0.1, contact 1; its units are other than these)
    w_adv: float = 1.0
    w_r1: float = 1.0
    r1_every: int = 4
    w_rec: float = 3.0
    w_cyc_content: float = 3.0
    w_cyc_style: float = 3.0
    w_dis: float = 1.0  # style disentanglement
    w_smooth_vel: float = 0.05  # physics: pose velocity (train-std units, squared)
    w_smooth_acc: float = 0.5  # physics: pose and global acceleration
    w_foot: float = 1.0  # physics: foot contact
    w_content: float = 1.0  # the transfer's frame content features Y against the input's (not in the paper)
    # a content classifier's cross-entropy on the transfer against the input's content label (a
    # content network trained first on the train takes, training.content; not in the paper; off in
    # the shipped model)
    w_content_net: float = 0.0
    # windows of the pseudo-pairs (DataConfig.distil) per iteration, each restyled like a real
    # window of its pair's style and held to the pair's target by the reconstruction terms,
    # weighted w_distil (not in the paper)
    distil_batch: int = 8
    w_distil: float = 1.0
    # reconstruction terms (training.losses.Losses)
    w_pos: float = 0.5
    w_vel: float = 1.0
    w_root: float = 1.0
    std_floor: float = 0.05
    means_per_style: int = 64  # train windows averaged into each style's exported mean feature
    val_windows: int = 64  # fixed val windows of the validation figures

    def networks(self, styles: tuple[str, ...]) -> MostConfig:
        return MostConfig(styles, window=self.window, dim=self.dim, heads=self.heads,
                          enc_blocks=self.enc_blocks, dec_blocks=self.dec_blocks, dis_blocks=self.dis_blocks,
                          ff_expand=self.ff_expand, residual=self.residual)


def tiny_config(**changes) -> Config:
    """A small, fast configuration with the real data path (tests)."""
    return replace(Config(window=16, dim=8, heads=2, enc_blocks=1, dec_blocks=1, batch=4,
                          means_per_style=4, val_windows=16), **changes)


def style_pairs(clips: Clips, length: int, styles: np.ndarray, rng: np.random.Generator
                ) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """Two ``length``-frame windows of each requested style, from takes of different contents where
    the style has them (the disentanglement loss's pair): ``(N, length, F)`` twice, and whether
    each pair's contents differ ``(N,)``."""
    spans = np.array([max(len(f) - length + 1, 0) for f in clips.features], dtype=float)
    first, second, differ = [], [], []
    for style in styles:
        p = spans * (clips.styles == style)
        if p.sum() == 0:
            raise MotionStyleError(f"no take of style {style} has the {length} frames a window needs")
        i = rng.choice(len(p), p=p / p.sum())
        other = p * (clips.contents != clips.contents[i])
        j = rng.choice(len(p), p=(other if other.sum() else p) / (other.sum() or p.sum()))
        differ.append(bool(other.sum()))
        for take, out in ((i, first), (j, second)):
            s = rng.integers(0, int(spans[take]))
            out.append(clips.features[take][s : s + length])
    return torch.from_numpy(np.stack(first)), torch.from_numpy(np.stack(second)), np.array(differ)


def val_targets(val: Clips, style: torch.Tensor, n_styles: int, length: int, rng: np.random.Generator
                ) -> torch.Tensor:
    """Each val window's target style: another style, among those with a val take of ``length``
    frames where some style has none (Bandai dataset-1 has no val takes)."""
    have = np.unique(val.styles[[len(f) >= length for f in val.features]])
    if len(have) == n_styles:
        return other_styles(style, n_styles, rng)
    return torch.from_numpy(np.array([rng.choice(have[have != s]) for s in style.tolist()]))


def content_change(fake: torch.Tensor, real: torch.Tensor) -> torch.Tensor:
    """How far the transfer's frame content features ``Y`` moved from the input's, relative to the
    input's own spread, so that scaling the features down cannot shrink it; the input's side is
    the target, not a thing to move."""
    real = real.detach()
    return (fake - real).pow(2).mean() / real.pow(2).mean().clamp_min(1e-6)


class Passes(nn.Module):
    """The generator side of one iteration as one forward call (so that ``DistributedDataParallel``
    sees one forward per backward): the transfer, its twin from the second style window (no
    gradient), the reconstruction, both cycles and the pseudo-pairs' transfers ("taught")."""

    def __init__(self, model: MoST, losses: Losses) -> None:
        super().__init__()
        self.model, self.losses = model, losses

    def full(self, frames: torch.Tensor, contacts: torch.Tensor) -> torch.Tensor:
        """encode() features of generated ``[root | rot6d]`` frames: FK positions and velocities
        (frame 0's velocity repeats frame 1's), the given contacts."""
        views = self.losses.views(frames)
        vel = torch.cat([views["vel"][:, :1], views["vel"]], dim=1)
        return torch.cat([frames, views["pos"].flatten(-2), vel.flatten(-2), contacts], dim=-1)

    def forward(self, content: torch.Tensor, style: torch.Tensor, style2: torch.Tensor,
                pairs: torch.Tensor, pair_refs: torch.Tensor) -> dict[str, torch.Tensor]:
        m = self.model
        contacts = content[..., self.losses.contact_cols]
        enc_c, enc_s = m.encoder(content), m.encoder(style)
        fake = m.transfer(enc_c, enc_s, content)
        with torch.no_grad():
            twin = m.transfer(enc_c, m.encoder(style2), content)
        rec = m.transfer(enc_c, enc_c, content)
        fake_full = self.full(fake, contacts)
        enc_f = m.encoder(fake_full)
        return {"fake": fake, "fake_full": fake_full, "twin": twin, "rec": rec,
                "cyc_content": m.transfer(enc_f, enc_c, fake_full),
                "cyc_style": m.transfer(enc_s, enc_f, style),
                "content_fake": enc_f[1], "content_in": enc_c[1],
                "taught": m(pairs, pair_refs) if len(pairs) else pairs}


class Trainer(ResumableTrainer):
    """The model, the discriminator, the model's weight average and the optimisers, with
    checkpoints in ``checkpoints/most_<seed>/`` (``checkpoint.pt``, ``losses.jsonl``)."""

    FOLDER = NAME
    LABEL = "most"
    SHOWN = ("rec", "dis", "adv")
    PARTS = ("most", "dis", "most_ema", "opt_g", "opt_d")

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True, device: torch.device | None = None) -> None:
        super().__init__(cfg, data, checkpoints, progress, device)
        mean, std = self.normalised_losses()
        self.content, self.content_info = None, None
        if cfg.w_content_net:
            with hardware.rank_zero_first():  # the others read the network rank 0 trained and saved
                self.content, self.content_info = content_network(
                    cfg, data, self.losses, self.dir / "content_net.pt", self.progress, self.device)
        net = cfg.networks(data.styles)
        torch.manual_seed(cfg.seed)
        self.most = MoST(net, mean, std).to(self.device)
        self.dis = Discriminator(net, mean, std).to(self.device)
        self.most_ema = copy.deepcopy(self.most).requires_grad_(False)
        self._passes = Passes(self.most, self.losses)
        self.passes = self.synced(self._passes)
        self.dis_synced = self.synced(self.dis)
        self.opt_g = torch.optim.Adam(self.most.parameters(), lr=cfg.lr, betas=cfg.betas,
                                      weight_decay=cfg.weight_decay)
        self.opt_d = torch.optim.Adam(self.dis.parameters(), lr=cfg.lr_dis, betas=cfg.betas,
                                      weight_decay=cfg.weight_decay)
        val_rng = np.random.default_rng([cfg.seed, 3])
        val = data.splits["val"]
        x, style, _ = windows(val, cfg.window, cfg.val_windows, val_rng)
        target = val_targets(val, style, len(data.styles), cfg.window, val_rng)
        s1, s2, _ = style_pairs(val, cfg.window, target.numpy(), val_rng)
        self.val_windows = tuple(t.to(self.device) for t in (x, style, target, s1, s2))
        self.in_std = torch.as_tensor(std, dtype=torch.float32, device=self.device)

    @property
    def model(self) -> MoST:
        """The model (the network the loop puts in train mode)."""
        return self.most

    def summary(self) -> dict:
        return {**super().summary(), "content_network": self.content_info}

    def physics(self, out: torch.Tensor, feet_of: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor,
                                                                          torch.Tensor]:
        """Velocity, acceleration and foot-contact terms of generated frames ``out`` (feet held in
        contact where the features ``feet_of`` have them)."""
        views = self.losses.views(out)
        body = pose(views["pos"])
        vel = (body[:, 1:] - body[:, :-1]) * (FPS / self.losses.vel_scale)
        acc = (vel[:, 1:] - vel[:, :-1]).pow(2).sum(-1).mean()
        root = views["root"] / self.losses.root_std
        acc = acc + (root[:, 1:] - root[:, :-1]).pow(2).mean()
        return vel.pow(2).sum(-1).mean(), acc, self.losses.foot(views, feet_of)

    def step(self, iteration: int) -> dict[str, float]:
        """One discriminator and one generator update; returns the loss terms."""
        cfg, n_styles = self.cfg, len(self.data.styles)
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, content = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        target = other_styles(style, n_styles, rng)
        s1, s2, _ = style_pairs(self.data.splits["train"], cfg.window, target.numpy(), rng)
        x, content, target, s1, s2 = self.shard(x, content, target, s1, s2)
        # the pseudo-pairs, each restyled like a real window of its pair's style
        pairs, pair_styles, pair_targets = self.pair_windows(rng)
        pair_refs = pairs if not len(pairs) else style_windows(
            self.data.splits["train"], cfg.window, pair_styles.cpu().numpy(), rng).to(self.device)

        # discriminator: real style windows of their style vs transfers to it
        self.dis.requires_grad_(True)
        with torch.no_grad():
            fake_full = self._passes.full(self.most(x, s1), x[..., self.losses.contact_cols])
        lazy = iteration % cfg.r1_every == 0
        real = s1.clone().requires_grad_(lazy)
        d_real = self.dis_synced(real).gather(1, target[:, None])[:, 0]
        r1 = torch.zeros((), device=self.device)
        if lazy:
            (grad,) = torch.autograd.grad(d_real.sum(), real, create_graph=True)
            r1 = 0.5 * (grad * self.in_std).pow(2).sum(dim=(1, 2)).mean()  # w.r.t. normalised input
        d_fake = self.dis_synced(fake_full).gather(1, target[:, None])[:, 0]
        critic = F.softplus(-d_real).mean() + F.softplus(d_fake).mean()
        self.opt_d.zero_grad()
        (critic + cfg.w_r1 * cfg.r1_every * r1).backward()
        self.opt_d.step()

        # encoder, modulator, generator
        self.dis.requires_grad_(False)
        out = self.passes(x, s1, s2, pairs, pair_refs)
        n_out = self.most.cfg.n_out
        adv = F.softplus(-self.dis(out["fake_full"]).gather(1, target[:, None])[:, 0]).mean()
        rec = self.losses.distance(out["rec"], x[..., :n_out])
        cyc_c = self.losses.distance(out["cyc_content"], x[..., :n_out])
        cyc_s = self.losses.distance(out["cyc_style"], s1[..., :n_out])
        dis = self.losses.distance(out["fake"], out["twin"])
        vel, acc, foot = self.physics(out["fake"], x)
        foot = 0.5 * (foot + self.losses.foot(self.losses.views(out["cyc_content"]), x))
        kept = content_change(out["content_fake"], out["content_in"])
        distil = (self.losses.distance(out["taught"], pair_targets) if len(pair_targets)
                  else torch.zeros((), device=self.device))
        classified = torch.zeros((), device=self.device)
        if self.content is not None:
            classified = F.cross_entropy(self.content(self.losses.views(out["fake"])["content"])[0], content)
        total = (cfg.w_adv * adv + cfg.w_rec * rec + cfg.w_cyc_content * cyc_c + cfg.w_cyc_style * cyc_s
                 + cfg.w_dis * dis + cfg.w_smooth_vel * vel + cfg.w_smooth_acc * acc + cfg.w_foot * foot
                 + cfg.w_content * kept + cfg.w_content_net * classified + cfg.w_distil * distil)
        self.opt_g.zero_grad()
        total.backward()
        self.opt_g.step()
        update_average(self.most_ema, self.most, cfg.ema)
        return {"adv": adv.item(), "critic": critic.item(), "r1": r1.item(), "rec": rec.item(),
                "cyc_content": cyc_c.item(), "cyc_style": cyc_s.item(), "dis": dis.item(),
                "vel": vel.item(), "acc": acc.item(), "foot": foot.item(), "content": kept.item(),
                "content_net": classified.item(), **({"distil": distil.item()} if len(pair_targets) else {})}

    @torch.no_grad()
    def validate(self, model: MoST | None = None) -> dict[str, float]:
        """On fixed val windows with the weight average (or ``model``): the reconstruction of a
        window restyled like itself; how far apart the transfers from two style windows of one
        style and different contents are (disentanglement, summed reconstruction terms); how far
        transfers move the pose from the input (m); and how often a transfer's style feature is
        nearest the target style's mean (means over the val windows' own style features)."""
        m = model or self.most_ema
        x, style, target, s1, s2 = self.val_windows
        n_out = m.cfg.n_out
        enc_x = m.encoder(x)
        rec = self.losses.reconstruction(self.losses.views(m.transfer(enc_x, enc_x, x)),
                                         self.losses.views(x[..., :n_out]))
        fake = m.transfer(enc_x, m.encoder(s1), x)
        twin = m.transfer(enc_x, m.encoder(s2), x)
        moved = (pose(self.losses.views(fake)["pos"]) - pose(self.losses.views(x[..., :n_out])["pos"]))
        full = Passes(m, self.losses).full(fake, x[..., self.losses.contact_cols])
        s_fake = m.encoder(full)[0].flatten(1)
        s_real = enc_x[0].flatten(1)
        # the styles these val windows show (Bandai dataset-1 has no val takes): an absent style's
        # mean would be infinite, and cdist's matrix form turns that into NaN for every style
        present = style.unique()
        means = torch.stack([s_real[style == k].mean(0) for k in present])
        nearest = present[torch.cdist(s_fake, means).argmin(-1)]
        return {**val_scores(rec),
                "val_disentangle": round(self.losses.distance(fake, twin).item(), 5),
                "val_pose_change_m": round(moved.norm(dim=-1).mean().item(), 4),
                "val_transfer_style_acc": round(float((nearest == target).float().mean()), 4)}


@torch.no_grad()
def style_means(model: MoST, clips: Clips, n_styles: int, count: int, seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Every style's mean style feature ``S`` and mean content feature ``C`` ``(n_styles, P, D)``
    over ``count`` random windows of its train takes (what ``target_style`` restyles towards)."""
    rng = np.random.default_rng([seed, 7])
    features = StyleFeatures(model).eval()
    s, c = [], []
    for k in range(n_styles):
        x = style_windows(clips, model.cfg.window, np.full(count, k), rng).to(next(model.parameters()).device)
        got = features(x)
        s.append(got[0].mean(0).cpu().numpy())
        c.append(got[1].mean(0).cpu().numpy())
    return np.stack(s), np.stack(c)


def paper_differences(cfg: Config) -> list[str]:
    """What the card says of the run's networks and losses against the paper's."""
    width = (f"body-part tokens of width {cfg.dim} ({cfg.heads} heads)"
             + (" as the paper's" if cfg.dim == 48 else " instead of 48"))
    return [
        (f"{width}, {cfg.enc_blocks} + 1 encoder and {cfg.dec_blocks} generator blocks (the paper's code: "
         f"2 + 1 and 3), {cfg.window}-frame windows at 30 fps instead of 200 at 60 fps (2-hour CPU budget; "
         "the stream's windows)"),
        ("6D rotations, positions, velocities and foot contacts per joint, the root block "
         "(facing-frame velocity, pelvis height, yaw rate) as the global translation and velocity"),
        "sinusoidal frame positions and learned part positions; no dropout",
        *(["a residual generator: its heads give a change to the content window's own frames (zero "
           "at the start), not the frames"] if cfg.residual else []),
        ("losses in the shared units (rotation angle, FK positions and velocities, root); the "
         "physics terms on FK pose velocity and acceleration, the root block's change and the "
         "feet's speed at the content window's contacts (transfer and content cycle)"
         + (f"; a content term (weight {cfg.w_content}): the transfer's frame content features "
            "against the input's, relative to their spread" if cfg.w_content else "")
         + (f"; a content classifier's cross-entropy on the transfer (weight {cfg.w_content_net}; "
            "a content network trained on the train takes first)" if cfg.w_content_net else "")),
        (f"Adam betas {cfg.betas}, weight decay {cfg.weight_decay}, learning rate {cfg.lr} "
         f"(discriminator {cfg.lr_dis}), batch {cfg.batch}, lazy R1 every {cfg.r1_every}"),
    ]


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "",
          log_every: int = 25, val_every: int = 500, device: str | None = None,
          licence: str | None = None) -> dict | None:
    """Train (resuming when asked) on ``device`` (default: the best there is; under ``torchrun``, in
    every process), export the weight average with every style's mean features to ``out_dir``;
    returns the card (None in the processes other than rank 0, which export nothing)."""
    fitted = fit_for_export(Trainer, cfg, data, checkpoints, threads, device, progress, resume, minutes,
                            iterations, log_every, val_every, command, licence)
    if fitted is None:  # not rank 0
        return None
    trainer, data, record, probe = fitted
    model = trainer.most_ema.eval()
    means = style_means(model, data.splits["train"], len(data.styles), cfg.means_per_style, cfg.seed)
    info = {
        **record,
        "exported": f"exponential moving average of the model's weights (decay {cfg.ema}); every "
                    f"style's mean style features over {cfg.means_per_style} train windows",
        "differences_from_paper": paper_differences(cfg),
    }
    return write_model(model.cpu(), out_dir / f"{NAME}.onnx", info, probe, means)
