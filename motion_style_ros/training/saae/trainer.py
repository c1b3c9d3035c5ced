"""SAAE training (the plain SAAE, Model1 and Model2 of the ESANN 2018 seed) on Bandai takes: the
config and the trainer's step and validation (the loop is ``training.loop.ResumableTrainer``, the
export ``training.saae.export``).

Each iteration draws windows of real train takes and:

1. updates the **prior discriminator** on N(0, I) samples (real) against the encoder's content codes
   (fake), non-saturating loss;
2. updates the encoder, the decoder and the style critics on the paper's loss: the reconstruction
   ``delta(x, d(e(x), s))`` (here the shared terms of ``training.losses.Losses``: rotation angle, FK
   positions and velocities, root, in place of a plain Euclidean distance on 70-dim frames), the
   encoder fooling the prior discriminator, and (Model1, Model2) the style discriminator on the
   content code read through a gradient-reversal layer (its scale ramps from 0 to 1 over
   ``reverse_ramp`` iterations, as Ganin and Lempitsky do, so that the first codes are not scrambled
   before the decoder can use them). Model2 adds the style code's classifier (gradient as it is).
   Two additions, both off at their defaults except the foot term: ``w_foot`` (feet the input holds
   still stay still) and ``w_cycle`` (a window decoded with another window's style input is
   re-encoded to the same content code and, in Model2, the other style code and label).

The exponential moving averages of the encoder, decoder and Model2's style classifier are exported;
Model2's card also holds each style's mean style code over train windows (the style input a style
label stands for) and its spread.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.models.saae import (
    Critic,
    Decoder,
    Encoder,
    SaaeConfig,
    positions,
    style_input,
)
from motion_style_ros.models.style_erd import reverse
from motion_style_ros.training.data import (
    Data,
    DataConfig,
    data_tag,
    style_windows,
    windows,
)
from motion_style_ros.training.loop import (
    CHECKPOINTS,
    ResumableTrainer,
    fit_for_export,
    update_average,
)
from motion_style_ros.training.losses import val_scores
from motion_style_ros.training.saae.export import model_name, write_model

NAME = "saae"
STYLE_CODE_WINDOWS = 64  # train windows per style whose style codes give the card's per-style code


@dataclass(frozen=True)
class Config(DataConfig):
    """Everything that shapes an SAAE run, the seed and data fields of :class:`DataConfig` first;
    a checkpoint resumes only under the same config."""

    variant: str = "model2"  # saae | model1 | model2
    style_dim: int = 5  # Model2's style code (the paper: 2, 3, 5)
    # networks (models.saae.SaaeConfig; the paper gives no sizes)
    window: int = 48
    hidden: int = 256
    content_dim: int = 32
    critic_hidden: int = 128
    # optimisation
    batch: int = 32
    lr: float = 5e-4  # encoder, decoder, style critics
    lr_prior: float = 2e-4  # the prior discriminator
    betas: tuple[float, float] = (0.5, 0.999)
    clip: float = 1.0  # gradient norm of the autoencoder's update (GRUs)
    ema: float = 0.999
    # loss weights
    w_prior: float = 1.0  # the encoder fooling the prior discriminator
    w_style: float = 1.0  # the reversed-gradient style discriminator on the content code
    reverse_ramp: int = 2000  # iterations over which the reversal scale goes 0 -> 1
    w_class: float = 1.0  # Model2: the style code's classifier
    w_foot: float = 0.5
    w_cycle: float = 0.0
    # windows of the pseudo-pairs (DataConfig.distil) per iteration, each decoded from its own
    # content code with its pair's style input (Model2: the code of a real window of that style)
    # and held to the pair's target by the reconstruction terms, weighted w_distil (not in the
    # paper; the plain SAAE has no style input to learn it from)
    distil_batch: int = 8
    w_distil: float = 1.0
    # reconstruction terms (training.losses.Losses)
    w_pos: float = 0.5
    w_vel: float = 1.0
    w_root: float = 1.0
    std_floor: float = 0.05

    def networks(self, styles: tuple[str, ...]) -> SaaeConfig:
        return SaaeConfig(styles, self.variant, window=self.window, hidden=self.hidden,
                          content_dim=self.content_dim, style_dim=self.style_dim,
                          critic_hidden=self.critic_hidden)


def tiny_config(**changes) -> Config:
    """A small, fast configuration with the real data path (tests)."""
    return replace(Config(window=16, hidden=16, content_dim=6, style_dim=3, critic_hidden=16, batch=8,
                          reverse_ramp=4), **changes)


class Trainer(ResumableTrainer):
    """Encoder, decoder, prior discriminator, style discriminator (Model1, Model2), style classifier
    (Model2), the weight averages and the optimisers, with checkpoints in
    ``checkpoints/<model name>_<seed>/`` (one folder per variant and style size)."""

    LABEL = "saae"
    SHOWN = ("rec", "prior", "critic")
    PARTS = ("enc", "dec", "prior_critic", "style_critic", "classifier", "enc_ema", "dec_ema",
             "classifier_ema", "opt_g", "opt_d")
    FOLDER = NAME

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True, device: torch.device | None = None) -> None:
        super().__init__(cfg, data, checkpoints, progress, device)
        self.dir = checkpoints / f"{model_name(cfg.variant, cfg.style_dim)}{data_tag(cfg.data)}_{cfg.seed}"
        mean, std = self.normalised_losses()
        net = self.net = cfg.networks(data.styles)
        if data.pairs is not None and net.variant == "saae":
            raise MotionStyleError("--distil: the plain SAAE has no style input to distil into; "
                                   "--variant model1 and model2 have")
        n = len(data.styles)
        torch.manual_seed(cfg.seed)
        self.enc, self.dec = Encoder(net, mean, std).to(self.device), Decoder(net, mean, std).to(self.device)
        self.prior_critic = Critic(net.content_dim, net.critic_hidden, 1).to(self.device)
        # plain SAAE: the style critics exist (one checkpoint layout) but are never used
        self.style_critic = Critic(net.content_dim, net.critic_hidden, n).to(self.device)
        self.classifier = Critic(max(net.style_dim, 1), net.critic_hidden, n).to(self.device)
        self.enc_synced, self.dec_synced, self.style_synced, self.classifier_synced, self.prior_synced = (
            self.synced(m) for m in (self.enc, self.dec, self.style_critic, self.classifier, self.prior_critic))
        self.enc_ema, self.dec_ema, self.classifier_ema = (
            copy.deepcopy(m).requires_grad_(False) for m in (self.enc, self.dec, self.classifier))
        live = [*self.enc.parameters(), *self.dec.parameters()]
        if cfg.variant != "saae":
            live += self.style_critic.parameters()
        if cfg.variant == "model2":
            live += self.classifier.parameters()
        self.opt_g = torch.optim.Adam(live, lr=cfg.lr, betas=cfg.betas)
        self.opt_d = torch.optim.Adam(self.prior_critic.parameters(), lr=cfg.lr_prior, betas=cfg.betas)
        val_rng = np.random.default_rng([cfg.seed, 3])
        self.val_windows = tuple(t.to(self.device) for t in windows(data.splits["val"], cfg.window, 64, val_rng))

    @property
    def model(self) -> Decoder:
        return self.dec

    def train_mode(self, on: bool) -> None:
        for m in (self.enc, self.dec, self.prior_critic, self.style_critic, self.classifier):
            m.train(on)

    def full(self, frames: torch.Tensor, contacts: torch.Tensor) -> torch.Tensor:
        """encode() features of decoded ``[root | rot6d]`` frames (FK positions and velocities, frame
        0's velocity that of frame 1; the contacts given), to be encoded again."""
        views = self.losses.views(frames)
        vel = torch.cat([views["vel"][:, :1], views["vel"]], dim=1)
        return torch.cat([frames, views["pos"].flatten(-2), vel.flatten(-2), contacts], dim=-1)

    def step(self, iteration: int) -> dict[str, float]:
        """One prior-discriminator update and one autoencoder update; returns the loss terms."""
        cfg, net = self.cfg, self.net
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, _ = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        z = torch.from_numpy(rng.standard_normal((cfg.batch, cfg.content_dim)).astype(np.float32))
        order = torch.from_numpy(rng.permutation(cfg.batch))  # whose style input each row borrows (cycle)
        x, style, z, order = self.shard(x, style, z, order)
        order = order.argsort().argsort() % len(x)  # a permutation of this process's rows
        pos = positions(cfg.window, cfg.window, len(x)).to(self.device)

        # the prior discriminator: N(0, I) samples real, content codes fake
        self.prior_critic.requires_grad_(True)
        with torch.no_grad():
            codes = self.enc(x)[0]
        critic = F.softplus(-self.prior_synced(z)).mean() + F.softplus(self.prior_synced(codes)).mean()
        self.opt_d.zero_grad()
        critic.backward()
        self.opt_d.step()

        # the autoencoder and the style critics
        self.prior_critic.requires_grad_(False)
        content, code = self.enc_synced(x)
        given = style_input(net, style, code)
        out = self.dec_synced(content, given, pos)
        views = self.losses.views(out)
        terms = self.losses.reconstruction(views, self.losses.views(x[..., : net.n_out]))
        rec = sum(terms.values())
        prior = F.softplus(-self.prior_critic(content)).mean()
        foot = self.losses.foot(views, x)
        distil = self.distil(rng)
        total = rec + cfg.w_prior * prior + cfg.w_foot * foot + cfg.w_distil * distil
        zero = torch.zeros((), device=self.device)
        hidden = cls = cycle = zero
        if cfg.variant != "saae":
            scale = min(1.0, iteration / max(cfg.reverse_ramp, 1))
            hidden = F.cross_entropy(self.style_synced(reverse(content, scale)), style)
            total = total + cfg.w_style * hidden
        if cfg.variant == "model2":
            cls = F.cross_entropy(self.classifier_synced(code), style)
            total = total + cfg.w_class * cls
        if cfg.w_cycle:
            other = given[order]
            again, again_code = self.enc_synced(self.full(self.dec_synced(content, other, pos),
                                                          x[..., self.losses.contact_cols]))
            cycle = (again - content.detach()).pow(2).mean()
            if cfg.variant == "model2":
                cycle = (cycle + (again_code - code.detach()[order]).pow(2).mean()
                         + F.cross_entropy(self.classifier_synced(again_code), style[order]))
            total = total + cfg.w_cycle * cycle
        self.opt_g.zero_grad()
        total.backward()
        torch.nn.utils.clip_grad_norm_([p for g in self.opt_g.param_groups for p in g["params"]], cfg.clip)
        self.opt_g.step()
        for avg, live in ((self.enc_ema, self.enc), (self.dec_ema, self.dec), (self.classifier_ema, self.classifier)):
            update_average(avg, live, cfg.ema)
        return {"rec": rec.item(), "rot": terms["rot"].item(), "prior": prior.item(), "critic": critic.item(),
                "hidden_style": hidden.item(), "cls": cls.item(), "foot": foot.item(), "cycle": cycle.item(),
                **({"distil": distil.item()} if self.data.pairs is not None else {})}

    def distil(self, rng: np.random.Generator) -> torch.Tensor:
        """The pseudo-pairs' term: each pair's input decoded from its content code with its style's
        input (Model2: the code of a real window of the style, as the style's mean code at run
        time), against its target (zero without pairs)."""
        pairs, styles, targets = self.pair_windows(rng)
        if not len(pairs):
            return torch.zeros((), device=self.device)
        code = None
        if self.net.variant == "model2":
            real = style_windows(self.data.splits["train"], self.cfg.window, styles.cpu().numpy(), rng)
            code = self.enc_synced(real.to(self.device))[1]
        out = self.dec_synced(self.enc_synced(pairs)[0], style_input(self.net, styles, code),
                              positions(self.cfg.window, self.cfg.window, len(pairs)).to(self.device))
        return self.losses.distance(out, targets)

    @torch.no_grad()
    def validate(self, live: bool = False) -> dict[str, float]:
        """On fixed val windows with the weight averages (or the live networks): the reconstruction,
        how far the content codes are from N(0, I) (mean of their means' squares, mean of their
        variances), how often the style discriminator recovers the style from the content code
        (chance is what Model1 and Model2 aim at) and, in Model2, how often the style code's
        classifier does and how often it recognises the style of a window decoded with another
        window's style code."""
        cfg, net = self.cfg, self.net
        enc, dec, classifier = (self.enc, self.dec, self.classifier) if live else (
            self.enc_ema, self.dec_ema, self.classifier_ema)
        x, style, _ = self.val_windows
        content, code = enc(x)
        pos = positions(cfg.window, cfg.window, len(x)).to(self.device)
        out = dec(content, style_input(net, style, code), pos)
        rec = self.losses.reconstruction(self.losses.views(out), self.losses.views(x[..., : net.n_out]))
        scores = {**val_scores(rec),
                  "val_code_mean_sq": round(float(content.mean(0).pow(2).mean()), 4),
                  "val_code_var": round(float(content.var(0).mean()), 4)}
        if cfg.variant != "saae":
            hidden = self.style_critic(content).argmax(-1)
            scores["val_content_style_acc"] = round(float((hidden == style).float().mean()), 4)
        if cfg.variant == "model2":
            scores["val_style_code_acc"] = round(float((classifier(code).argmax(-1) == style).float().mean()), 4)
            order = torch.roll(torch.arange(len(x), device=self.device), 1)
            moved = dec(content, code[order], pos)
            read = classifier(enc(self.full(moved, x[..., self.losses.contact_cols]))[1]).argmax(-1)
            scores["val_transfer_style_acc"] = round(float((read == style[order]).float().mean()), 4)
        return scores

    @torch.no_grad()
    def style_inputs(self) -> tuple[np.ndarray, np.ndarray]:
        """Each style's decoder style input and spread ``(S, style_width)``: one-hot and 0 (Model1),
        Model2's mean and std of the style codes (weight averages) of train windows of the style,
        0 and 0 (plain SAAE)."""
        n, net = len(self.data.styles), self.net
        if net.variant == "model1":
            return np.eye(n), np.zeros((n, n))
        if net.variant == "saae":
            return np.zeros((n, 1)), np.zeros((n, 1))
        rng = np.random.default_rng([self.cfg.seed, 7])
        means, stds = [], []
        for s in range(n):
            x = style_windows(self.data.splits["train"], self.cfg.window, np.full(STYLE_CODE_WINDOWS, s), rng)
            code = self.enc_ema(x.to(self.device))[1].cpu().numpy()
            means.append(code.mean(0))
            stds.append(code.std(0))
        return np.array(means), np.array(stds)


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "",
          log_every: int = 25, val_every: int = 500, device: str | None = None,
          licence: str | None = None) -> dict | None:
    """Train (resuming when asked) on ``device``, export the weight averages to ``out_dir`` as
    :func:`~motion_style_ros.training.saae.export.model_name`; returns the card (None in processes
    other than rank 0)."""
    fitted = fit_for_export(Trainer, cfg, data, checkpoints, threads, device, progress, resume, minutes,
                            iterations, log_every, val_every, command, licence)
    if fitted is None:  # not rank 0
        return None
    trainer, data, record, probe = fitted
    info = {
        **record,
        "exported": f"exponential moving averages of the encoder's, decoder's and style classifier's weights "
                    f"(decay {cfg.ema})",
        "differences_from_paper": [
            (f"{cfg.window}-frame windows at 30 fps (1.6 s; the paper's 200 frames were 1.7 s), bidirectional "
             f"GRU encoder and GRU decoder of {cfg.hidden} units, a {cfg.content_dim}-dim content code (the "
             "paper gives no sizes; these fit a 2-hour CPU budget)"),
            ("frames are the package's features (260 in; [root | rot6d], 130, out) instead of 70-dim "
             "frames; the decoder also reads each frame's position in the window"),
            ("reconstruction by rotation angle, FK positions, velocities and root (training.losses) "
             "instead of a Euclidean distance; a foot-contact term"
             + (f" (weight {cfg.w_foot})" if cfg.w_foot else " (off)")),
            (f"the gradient reversal's scale ramps 0 -> 1 over {cfg.reverse_ramp} iterations; non-saturating "
             "adversarial losses; Adam betas "
             f"{cfg.betas}, learning rates {cfg.lr} / {cfg.lr_prior} (prior discriminator), batch {cfg.batch}"),
            *([f"a latent cycle term (weight {cfg.w_cycle})"] if cfg.w_cycle else []),
        ],
    }
    trainer.train_mode(False)
    inputs, spread = trainer.style_inputs()
    name = model_name(cfg.variant, cfg.style_dim)
    classifier = trainer.classifier_ema.cpu() if cfg.variant == "model2" else None
    return write_model(trainer.enc_ema.cpu(), trainer.dec_ema.cpu(), classifier, out_dir / f"{name}.onnx",
                       inputs, spread, info, probe)
