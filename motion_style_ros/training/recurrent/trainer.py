"""Style-ERD training on Bandai Namco takes: the config, the content network of the perceptual loss,
and the trainer's step and validation (the loop is ``training.loop.ResumableTrainer``, the export
``training.recurrent.export``).

One run: (1) the content network (the perceptual loss's feature extractor) is trained on content
labels, or loaded from the checkpoint folder; (2) the generator and the FT-Att discriminator train
adversarially on windows of real takes; (3) the exponential moving average of the generator's
weights is exported. Each window is used twice per iteration: with its own style as the target
(reconstruction loss) and with a random other style (adversarial and perceptual losses). The
evaluation judges in ``models/`` are never used here.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion_style_ros.models.style_erd import ErdConfig, FTAttDiscriminator, StyleAdversary, StyleERD
from motion_style_ros.training import hardware
from motion_style_ros.training.data import (
    Data,
    other_styles,
    windows,
)
from motion_style_ros.training.loop import (
    CHECKPOINTS,
    ResumableTrainer,
    fit_for_export,
    update_average,
)
from motion_style_ros.training.content import FRAME, ContentConfig, content_network, frames
from motion_style_ros.training.losses import val_scores
from motion_style_ros.training.recurrent.export import write_model

NAME = "style_erd"


@dataclass(frozen=True)
class Config(ContentConfig):
    """Everything that shapes a Style-ERD run, the seed and data fields of :class:`DataConfig`
    and the content network's (:class:`ContentConfig`) first; a checkpoint resumes only under the
    same config."""

    # generator: models.style_erd.ErdConfig's sizes (shallower and wider than the paper's; why there)
    encoder: tuple[int, ...] = ErdConfig.encoder
    latent: int = ErdConfig.latent
    neutral_layers: int = ErdConfig.neutral_layers
    style_layers: int = ErdConfig.style_layers
    decoder: tuple[int, ...] = ErdConfig.decoder
    # windows: the generator runs crops * crop_frames + 1 frames from its initial state (the first
    # frame only gives the next one its velocity); the discriminator sees crop_frames-frame crops
    batch: int = 32
    crops: int = 3
    crop_frames: int = 24
    # optimisation (Adam; 5x the paper's learning rates, which are too slow for a 2-hour budget)
    lr_gen: float = 5e-4
    lr_dis: float = 2e-4
    ema: float = 0.999
    # loss weights: reconstruction terms are in radians (rotations) and train-std units
    w_pos: float = 0.5
    w_vel: float = 1.0
    w_root: float = 1.0
    w_adv: float = 1.0
    w_per: float = 0.1
    w_gp: float = 10.0
    # foot contact (Style-ERD's own loss): a foot joint the input holds still stays still in the
    # transferred output (squared velocity where the input's contact feature is 1); off in the
    # shipped model, 0.5 in the 22-style run
    w_foot: float = 0.0
    # a style adversary on the neutral stack's output (models.style_erd.StyleAdversary: the
    # generator leaves the input's style out of it); not in the paper, off in the shipped model
    w_style_adversary: float = 0.0
    lr_adversary: float = 2e-4
    # windows of the unlabelled clips (DataConfig.unlabelled) per iteration, each restyled into a
    # random style: critic and content terms only (they have no style to reconstruct)
    unlabelled_batch: int = 8
    # windows of the pseudo-pairs (DataConfig.distil) per iteration, each stylized into its pair's
    # style and held to the pair's target by the reconstruction terms, weighted w_distil
    distil_batch: int = 8
    w_distil: float = 1.0
    # the adversarial and perceptual weights ramp up linearly over the first iterations, so the
    # generator reconstructs plausible motion before the critics push it around
    warmup: int = 2000
    std_floor: float = 0.05
    # critics
    dis_widths: tuple[int, ...] = (128, 96, 64)
    dis_features: int = 16

    @property
    def window(self) -> int:
        return self.crops * self.crop_frames + 1

    def erd(self, styles: tuple[str, ...]) -> ErdConfig:
        return ErdConfig(styles, self.neutral, encoder=self.encoder, latent=self.latent,
                         neutral_layers=self.neutral_layers, style_layers=self.style_layers,
                         decoder=self.decoder)


def tiny_config(**changes) -> Config:
    """A small, fast configuration with the real data path (tests)."""
    return replace(Config(encoder=(16,), latent=8, neutral_layers=2, style_layers=2, decoder=(16,),
                          batch=4, crops=1, crop_frames=12, dis_widths=(16,), dis_features=4,
                          content_widths=(16,), content_iterations=5, content_batch=4, warmup=10),
                   **changes)


def _onehot(index: torch.Tensor, n: int, repeat: int = 1) -> torch.Tensor:
    return F.one_hot(index, n).float().repeat_interleave(repeat, dim=0)


class _Stylize(nn.Module):
    """The generator's training path as a module's forward (what DistributedDataParallel wraps)."""

    def __init__(self, model: StyleERD) -> None:
        super().__init__()
        self.model = model

    def forward(self, features: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.model.stylize(features, target, with_neutral=True)


class Trainer(ResumableTrainer):
    """Generator, discriminator, their optimisers and the generator's weight average, with
    checkpoints in ``checkpoints/recurrent_<seed>/`` (``checkpoint.pt``, ``content_net.pt``,
    ``losses.jsonl``)."""

    FOLDER = "recurrent"
    LABEL = "style-erd"
    SHOWN = ("rec", "adv", "critic")
    PARTS = ("model", "ema", "dis", "opt_g", "opt_d")

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True, device: torch.device | None = None) -> None:
        super().__init__(cfg, data, checkpoints, progress, device)
        mean, std = self.normalised_losses()
        with hardware.rank_zero_first():  # the others read the network rank 0 trained and saved
            self.content, self.content_info = content_network(cfg, data, self.losses, self.dir / "content_net.pt",
                                                              self.progress, self.device)
        torch.manual_seed(cfg.seed)
        self.model = StyleERD(cfg.erd(data.styles), mean, std, mean[:FRAME], std[:FRAME]).to(self.device)
        self.ema = copy.deepcopy(self.model).requires_grad_(False)
        self.dis = FTAttDiscriminator(self.losses.pv_cols.stop - self.losses.pv_cols.start,
                                      len(data.styles), len(data.contents), cfg.crop_frames,
                                      cfg.dis_widths, cfg.dis_features).to(self.device)
        # each branch runs only on the windows that target its style, so some may get no gradient
        self.stylize = self.synced(_Stylize(self.model), unused=True)
        self.dis_synced = self.synced(self.dis)
        self.opt_g = torch.optim.Adam(self.model.parameters(), lr=cfg.lr_gen)
        self.opt_d = torch.optim.Adam(self.dis.parameters(), lr=cfg.lr_dis)
        self.adversary = None
        if cfg.w_style_adversary:
            self.adversary = StyleAdversary(cfg.latent, len(data.styles)).to(self.device)
            self.adversary_synced = self.synced(self.adversary)
            self.opt_a = torch.optim.Adam(self.adversary.parameters(), lr=cfg.lr_adversary)
            self.PARTS = (*type(self).PARTS, "adversary", "opt_a")
        val_rng = np.random.default_rng([cfg.seed, 3])
        self.val_windows = tuple(t.to(self.device) for t in windows(data.splits["val"], cfg.window, 128, val_rng))
        self.val_targets = other_styles(self.val_windows[1], len(data.styles), val_rng)

    def crops(self, pv: torch.Tensor) -> torch.Tensor:
        """``(B, crops * crop_frames, C)`` -> ``(B * crops, crop_frames, C)``: the discriminator's."""
        return pv.reshape(-1, self.cfg.crop_frames, pv.shape[-1])

    def step(self, iteration: int) -> dict[str, float]:
        """One discriminator and one generator update; returns the loss terms."""
        cfg, n_styles = self.cfg, len(self.data.styles)
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, content = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        x, style, content, other = self.shard(x, style, content, other_styles(style, n_styles, rng))
        batch = len(x)
        # the restyled windows: every labelled one into another style, then unlabelled ones into any
        source, target = x, other
        if self.data.unlabelled is not None:
            u, _, _ = windows(self.data.unlabelled, cfg.window, cfg.unlabelled_batch, rng)
            u, u_target = self.shard(u, torch.from_numpy(rng.integers(0, n_styles, len(u))))
            source, target = torch.cat([x, u]), torch.cat([other, u_target])
        pair_inputs, pair_styles, pair_targets = self.pair_windows(rng)
        output, neutral = self.stylize(torch.cat([x, source, pair_inputs]),
                                       torch.cat([style, target, pair_styles]))
        out = self.losses.views(output)
        rec = {k: v[:batch] for k, v in out.items()}
        fake = {k: v[batch:batch + len(source)] for k, v in out.items()}
        source_views = self.losses.views(frames(source))
        real = {k: v[:batch] for k, v in source_views.items()}
        with torch.no_grad():
            source_content, target_maps = self.content(source_views["content"])
        # an unlabelled window's content: what the content network reads in it
        contents = torch.cat([F.one_hot(content, len(self.data.contents)).float(),
                              source_content[batch:].softmax(-1)])
        labels_real = (_onehot(style, n_styles, cfg.crops), _onehot(content, len(self.data.contents), cfg.crops))
        labels_fake = (_onehot(target, n_styles, cfg.crops), contents.repeat_interleave(cfg.crops, dim=0))

        # critic: real -> 1, transferred -> -1, gradient penalty on real crops (LSGAN, paper eq. 5, 6)
        self.dis.requires_grad_(True)
        real_pv = self.crops(real["pv"]).requires_grad_(True)
        d_real = self.dis_synced(real_pv, *labels_real)
        (grad,) = torch.autograd.grad(d_real.sum(), real_pv, create_graph=True)
        gp = grad.pow(2).sum(dim=(1, 2)).mean()
        d_fake = self.dis_synced(self.crops(fake["pv"].detach()), *labels_fake)
        critic = (d_real - 1).pow(2).mean() + (d_fake + 1).pow(2).mean()
        self.opt_d.zero_grad()
        (critic + cfg.w_gp * gp).backward()
        self.opt_d.step()

        # generator: reconstruction + adversarial (D(fake) -> 0, eq. 4) + perceptual
        self.dis.requires_grad_(False)
        terms = self.losses.reconstruction(rec, real)
        distil = torch.zeros(())
        if len(pair_targets):
            taught = {k: v[batch + len(source):] for k, v in out.items()}
            distil = sum(self.losses.reconstruction(taught, self.losses.views(pair_targets)).values())
        adv = self.dis(self.crops(fake["pv"]), *labels_fake).pow(2).mean()
        _, maps = self.content(fake["content"])
        per = sum(F.mse_loss(a, b) for a, b in zip(maps, target_maps))
        foot = self.losses.foot(fake, source)
        ramp = min(1.0, (iteration + 1) / cfg.warmup) if cfg.warmup else 1.0
        total = (sum(terms.values()) + cfg.w_distil * distil
                 + ramp * (cfg.w_adv * adv + cfg.w_per * per + cfg.w_foot * foot))
        # the style adversary reads the input's style in the neutral stack's output of the
        # labelled windows at its own rate; the generator gets its gradient reversed and weighted,
        # so it learns to leave no style there
        told = torch.zeros(())
        if self.adversary is not None:
            told = F.cross_entropy(self.adversary_synced(neutral[:batch], ramp * cfg.w_style_adversary), style)
            total = total + told
            self.opt_a.zero_grad()
        self.opt_g.zero_grad()
        total.backward()
        self.opt_g.step()
        if self.adversary is not None:
            self.opt_a.step()
        update_average(self.ema, self.model, cfg.ema)
        return {**{k: v.item() for k, v in terms.items()}, "rec": sum(terms.values()).item(),
                "adv": adv.item(), "per": per.item(), **({"distil": distil.item()} if len(pair_targets) else {}), "foot": foot.item(), "critic": critic.item(), "gp": gp.item(),
                **({"style_told": told.item()} if self.adversary is not None else {})}

    @torch.no_grad()
    def validate(self, model: StyleERD | None = None) -> dict[str, float]:
        """Reconstruction loss of ``model`` (default: the weight average) on fixed val windows
        with their own style as the target, and how often our content network still recognises
        the content after transfer to another style."""
        model = model or self.ema
        x, style, content = self.val_windows
        real = self.losses.views(frames(x))
        rec = self.losses.reconstruction(self.losses.views(model.stylize(x, style)), real)
        fake = self.losses.views(model.stylize(x, self.val_targets))
        logits, _ = self.content(fake["content"])
        return {**val_scores(rec),
                "val_transfer_content_acc": round(float((logits.argmax(-1) == content).float().mean()), 4)}

    def summary(self) -> dict:
        """The loop's history and the content network's figures, for the model card."""
        return {**super().summary(), "content_network": self.content_info}


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "", log_every: int = 25,
          val_every: int = 500, device: str | None = None, licence: str | None = None) -> dict | None:
    """Train (resuming when asked) on ``device`` (default: the best there is; under ``torchrun``,
    in every process), export the weight-averaged generator to ``out_dir``; returns the model card
    (None in the processes other than rank 0, which export nothing)."""
    fitted = fit_for_export(Trainer, cfg, data, checkpoints, threads, device, progress, resume, minutes,
                            iterations, log_every, val_every, command, licence)
    if fitted is None:  # not rank 0
        return None
    trainer, data, record, probe = fitted
    info = {
        **record,
        "contents": list(data.contents),
        "exported": f"exponential moving average of the generator weights (decay {cfg.ema})",
        "differences_from_paper": [
            ("no input style or content label anywhere (a live stream has neither): the encoder "
             "must normalise the style itself, and the neutral stack has one learned initial state"),
            "2 + 2 LSTM layers of width 64 instead of 6 + 4 of width 32 (trains far faster on CPU)",
            "6D rotations (geodesic angle loss) and the root's velocity, height and yaw rate out",
            "targets: any other style for every input (not only neutral <-> other)",
            ("adversarial and perceptual weights ramp up over the first iterations; learning rates "
             "5x the paper's; gradient penalty weight 10"),
        ],
    }
    return write_model(trainer.ema.cpu(), out_dir / f"{NAME}.onnx", info, probe)


def load_generator(checkpoint: Path) -> StyleERD:
    """The weight-averaged generator of a training checkpoint (what the ONNX export holds)."""
    saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
    cfg = Config(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved["config"].items()})
    erd = cfg.erd(tuple(saved["styles"]))
    model = StyleERD(erd, np.zeros(erd.n_features), np.ones(erd.n_features),
                     np.zeros(erd.n_out), np.ones(erd.n_out))
    model.load_state_dict(saved["ema"])
    return model.eval()
