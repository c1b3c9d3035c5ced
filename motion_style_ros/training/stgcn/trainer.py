"""ST-GCN stylizer training (Park et al. 2021) on Bandai Namco takes: the config and the trainer's
step and validation (the loop is ``training.loop.ResumableTrainer``, the export
``training.stgcn.export``).

Each iteration draws windows of real train takes with a random other target style, and a target
style code either from the mapping network (a random ``z``; even iterations) or from the style
encoder on a real window of the target style (odd iterations), as the paper alternates them.
The discriminator learns real vs transferred per style (non-saturating loss, R1 penalty on real
windows); the generator, mapping network and style encoder learn from the adversarial,
style-reconstruction, diversity-sensitive, cycle and identity losses, plus two additions: a
style classifier head on the style encoder (real windows' labels, so a reference clip of unknown
style picks its head) and a foot-contact loss (feet the input holds still stay still). Cycle and
identity use the shared reconstruction terms (``training.losses.Losses``: rotation angle, FK
positions and velocities, root). The weight averages of the three networks are exported. The
evaluation judges in ``models/`` are never used here.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from motion_style_ros.models.stgcn import (
    Discriminator,
    Generator,
    MappingNetwork,
    StgcnConfig,
    StyleEncoder,
    pick,
)
from motion_style_ros.training.data import (
    Data,
    DataConfig,
    other_styles,
    style_windows,
    windows,
)
from motion_style_ros.training.loop import CHECKPOINTS, ResumableTrainer, fit_for_export, update_average
from motion_style_ros.training.losses import pose, val_scores
from motion_style_ros.training.stgcn.export import write_model

NAME = "stgcn"


@dataclass(frozen=True)
class Config(DataConfig):
    """Everything that shapes an ST-GCN run, the seed and data fields of :class:`DataConfig`
    first; a checkpoint resumes only under the same config."""

    # networks (models.stgcn.StgcnConfig); the paper's widths are (64, 128, 256)
    window: int = 48
    widths: tuple[int, int, int] = (32, 64, 128)
    style_dim: int = 64
    latent_dim: int = 16
    mapping_hidden: int = 256
    # optimisation: Adam with StarGAN v2's betas (the paper's beta1 0.99 is too slow here)
    batch: int = 8
    # windows of the unlabelled clips (DataConfig.unlabelled) per iteration, restyled into random
    # styles: adversarial, style, cycle and identity terms with the code the style encoder reads
    # in them (never shown to the critic as real, never in its classifier's loss)
    unlabelled_batch: int = 4
    # windows of the pseudo-pairs (DataConfig.distil) per iteration, each transferred with a
    # mapped code of its pair's style (a random z, as a latent seed gives) and held to the pair's
    # target by the reconstruction terms, weighted w_distil (not in the paper)
    distil_batch: int = 8
    w_distil: float = 1.0
    lr: float = 2e-4  # generator, style encoder, discriminator
    lr_mapping: float = 2e-5
    betas: tuple[float, float] = (0.0, 0.99)
    ema: float = 0.999
    # loss weights (the paper's are all 1)
    w_adv: float = 1.0
    w_r1: float = 1.0
    r1_every: int = 4
    w_sty: float = 1.0
    # decays linearly to 0 over ds_iterations. Measured on all normalised output channels (seed 1's
    # model), the seeds mostly moved the root path: poses 14 mm apart against 81 mm between
    # styles. Measured on the pelvis-relative pose without a cap (seed 2's run), the seeds drifted
    # 2.7 times further apart than the styles and styles stopped transferring (13 % recognised at
    # 4000 iterations against 89 %). With ds_cap (m), a pair of seeds is pushed apart only until
    # their poses differ by that much on average over the joints. Continuing seed 1's run with
    # ds_cap 0.05 and w_ds 12 for 25 minutes (seed 4) put seeds twice as far apart (28 mm against
    # 87 mm between styles) but cost style accuracy (0.87 against 0.93), content (0.91 against
    # 0.94) and FMD (11.9 against 6.6): not shipped.
    w_ds: float = 4.0
    ds_iterations: int = 20000
    ds_cap: float | None = None
    w_cyc: float = 1.0
    w_id: float = 1.0
    w_cls: float = 1.0
    w_foot: float = 1.0
    # reconstruction terms inside cycle and identity (see training.losses.Losses)
    w_pos: float = 0.5
    w_vel: float = 1.0
    w_root: float = 1.0
    std_floor: float = 0.05

    def networks(self, styles: tuple[str, ...]) -> StgcnConfig:
        return StgcnConfig(styles, window=self.window, widths=self.widths, style_dim=self.style_dim,
                           latent_dim=self.latent_dim, mapping_hidden=self.mapping_hidden)


def tiny_config(**changes) -> Config:
    """A small, fast configuration with the real data path (tests)."""
    return replace(Config(window=16, widths=(8, 8, 16), style_dim=8, mapping_hidden=16, batch=4,
                          ds_iterations=10), **changes)


def _mean_over(rows: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """The mean of ``values`` over the ``rows`` chosen (0 where none is: under torchrun a process's
    share of a batch may hold unlabelled windows only)."""
    return (values * rows).sum() / rows.sum().clamp(min=1)


def _at(logits: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
    """Each row's logit of its style: ``(B, S)``, ``(B,)`` -> ``(B,)``."""
    return logits.gather(1, style[:, None])[:, 0]


class Trainer(ResumableTrainer):
    """Generator, mapping network, style encoder, discriminator, the weight averages of the first
    three and the optimisers, with checkpoints in ``checkpoints/stgcn_<seed>/`` (``checkpoint.pt``,
    ``losses.jsonl``)."""

    FOLDER = NAME
    LABEL = "st-gcn"
    SHOWN = ("rec", "adv", "critic")
    PARTS = ("gen", "mapping", "encoder", "dis", "gen_ema", "mapping_ema", "encoder_ema",
             "opt_g", "opt_d")
    # what a run continuing another (train's init_from) must share with it
    NETWORK_SETTINGS = ("datasets", "data", "window", "widths", "style_dim", "latent_dim", "mapping_hidden",
                        "std_floor")

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True, device: torch.device | None = None) -> None:
        super().__init__(cfg, data, checkpoints, progress, device)
        mean, std = self.normalised_losses()
        net = cfg.networks(data.styles)
        torch.manual_seed(cfg.seed)
        self.gen, self.mapping, self.encoder, self.dis = (m.to(self.device) for m in (
            Generator(net, mean, std), MappingNetwork(net), StyleEncoder(net, mean, std),
            Discriminator(net, mean, std)))
        # the networks whose gradients are averaged over processes (the discriminator only in its
        # own update: the generator's reads it frozen)
        self.gen_synced, self.mapping_synced, self.encoder_synced, self.dis_synced = (
            self.synced(m) for m in (self.gen, self.mapping, self.encoder, self.dis))
        self.gen_ema, self.mapping_ema, self.encoder_ema = (
            copy.deepcopy(m).requires_grad_(False) for m in (self.gen, self.mapping, self.encoder))
        self.opt_g = torch.optim.Adam([
            {"params": [*self.gen.parameters(), *self.encoder.parameters()]},
            {"params": self.mapping.parameters(), "lr": cfg.lr_mapping}], lr=cfg.lr, betas=cfg.betas)
        self.opt_d = torch.optim.Adam(self.dis.parameters(), lr=cfg.lr, betas=cfg.betas)
        val_rng = np.random.default_rng([cfg.seed, 3])
        self.val_windows = tuple(t.to(self.device) for t in windows(data.splits["val"], cfg.window, 64, val_rng))
        self.val_targets = other_styles(self.val_windows[1], len(data.styles), val_rng)
        self.in_std = torch.as_tensor(std, dtype=torch.float32, device=self.device)
        self.out_std = torch.as_tensor(std[: net.n_out], dtype=torch.float32, device=self.device)

    @property
    def model(self) -> Generator:
        """The generator (the network the loop puts in train mode)."""
        return self.gen

    def summary(self) -> dict:
        """The loop's history; ``content_network`` null (no content network here), as the shipped
        card has it."""
        return {**super().summary(), "content_network": None}

    def full(self, frames: torch.Tensor, contacts: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """encode() features ``(B, T, 260)`` of generated ``[root | rot6d]`` frames (FK positions
        and velocities; frame 0's velocity repeats frame 1's; contacts given), and their views."""
        views = self.losses.views(frames)
        vel = torch.cat([views["vel"][:, :1], views["vel"]], dim=1)
        return torch.cat([frames, views["pos"].flatten(-2), vel.flatten(-2), contacts], dim=-1), views

    def target_codes(self, iteration: int, target: torch.Tensor, rng: np.random.Generator,
                     mapping: MappingNetwork, encoder: StyleEncoder) -> tuple[torch.Tensor, torch.Tensor]:
        """Two target style codes per row of the global batch's ``target`` (on the CPU), this
        process's share: from noise (even iterations) or from real windows of the target style (odd
        iterations)."""
        if iteration % 2 == 0:
            z = torch.from_numpy(rng.standard_normal((2, len(target), self.cfg.latent_dim)).astype(np.float32))
            z0, z1, target = self.shard(z[0], z[1], target)
            onehot = F.one_hot(target, len(self.data.styles)).float()
            return mapping(z0, onehot), mapping(z1, onehot)
        refs = [style_windows(self.data.splits["train"], self.cfg.window, target.numpy(), rng)
                for _ in range(2)]
        *refs, target = self.shard(*refs, target)
        return pick(encoder(refs[0])[0], target), pick(encoder(refs[1])[0], target)


    def step(self, iteration: int) -> dict[str, float]:
        """One discriminator and one generator update; returns the loss terms."""
        cfg, n_styles = self.cfg, len(self.data.styles)
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, _ = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        target = other_styles(style, n_styles, rng)
        if self.data.unlabelled is not None:  # their style -1: unknown, read by the style encoder
            u, _, _ = windows(self.data.unlabelled, cfg.window, cfg.unlabelled_batch, rng)
            x, style = torch.cat([x, u]), torch.cat([style, torch.full((len(u),), -1)])
            target = torch.cat([target, torch.from_numpy(rng.integers(0, n_styles, len(u)))])
        code_rng = np.random.default_rng([cfg.seed, 4, iteration])
        s_trg, s_trg2 = self.target_codes(iteration, target, code_rng, self.mapping_synced, self.encoder_synced)
        x, style, target = self.shard(x, style, target)
        labelled = style >= 0
        contacts = x[..., self.losses.contact_cols]

        # discriminator: real windows of their own style vs transfers to the target style; the R1
        # penalty every r1_every iterations with that much more weight (lazy regularisation)
        self.dis.requires_grad_(True)
        with torch.no_grad():
            fake, _ = self.full(self.gen(x, s_trg), contacts)
        lazy = iteration % cfg.r1_every == 0
        x_real = x.clone().requires_grad_(lazy)
        d_real = _at(self.dis_synced(x_real), style.clamp(min=0))
        r1 = torch.zeros((), device=self.device)
        if lazy:
            (grad,) = torch.autograd.grad(d_real.sum(), x_real, create_graph=True)
            r1 = 0.5 * _mean_over(labelled, (grad * self.in_std).pow(2).sum(dim=(1, 2)))  # w.r.t. normalised input
        d_fake = _at(self.dis_synced(fake), target)
        critic = _mean_over(labelled, F.softplus(-d_real)) + F.softplus(d_fake).mean()
        self.opt_d.zero_grad()
        (critic + cfg.w_r1 * cfg.r1_every * r1).backward()
        self.opt_d.step()

        # generator, mapping network, style encoder
        self.dis.requires_grad_(False)
        out = self.gen_synced(x, s_trg)
        fake, fake_views = self.full(out, contacts)
        adv = F.softplus(-_at(self.dis(fake), target)).mean()
        sty = (s_trg - pick(self.encoder_synced(fake)[0], target)).abs().mean()
        with torch.no_grad():
            out2 = self.gen(x, s_trg2)
        if cfg.ds_cap is None:
            ds = ((out - out2) / self.out_std).abs().mean()
        else:  # per window: mean joint distance of the two poses, up to the cap
            apart = (pose(fake_views["pos"]) - pose(self.losses.views(out2)["pos"])).norm(dim=-1)
            ds = apart.mean(dim=(1, 2)).clamp(max=cfg.ds_cap).mean() / self.losses.pos_scale
        codes, logits = self.encoder_synced(x)
        s_src = pick(codes, torch.where(labelled, style, logits.detach().argmax(-1)))
        cls = _mean_over(labelled, F.cross_entropy(logits, style.clamp(min=0), reduction="none"))
        real = self.losses.views(x[..., : self.gen.cfg.n_out])
        cyc = sum(self.losses.reconstruction(self.losses.views(self.gen_synced(fake, s_src)), real).values())
        idt = sum(self.losses.reconstruction(self.losses.views(self.gen_synced(x, s_src)), real).values())
        # feet the input holds still (contact at this frame and the one before) stay still
        still = (contacts[:, 1:] * contacts[:, :-1])[..., None]
        foot_vel = fake_views["vel"][:, :, self.losses.feet]
        frames = self.mean_over_processes(still.sum())  # so N processes' mean is one's whole-batch term
        foot = (still * foot_vel.pow(2)).sum() / frames.clamp(min=1.0) / self.losses.vel_scale ** 2
        distil = self.distil(code_rng)
        w_ds = cfg.w_ds * max(0.0, 1.0 - iteration / cfg.ds_iterations)
        total = (cfg.w_adv * adv + cfg.w_sty * sty - w_ds * ds + cfg.w_cyc * cyc + cfg.w_id * idt
                 + cfg.w_cls * cls + cfg.w_foot * foot + cfg.w_distil * distil)
        self.opt_g.zero_grad()
        total.backward()
        self.opt_g.step()
        for avg, live in ((self.gen_ema, self.gen), (self.mapping_ema, self.mapping),
                          (self.encoder_ema, self.encoder)):
            update_average(avg, live, cfg.ema)
        return {"adv": adv.item(), "critic": critic.item(), "r1": r1.item(), "sty": sty.item(),
                "ds": ds.item(), "cyc": cyc.item(), "id": idt.item(), "cls": cls.item(),
                "foot": foot.item(), "rec": (cyc + idt).item(),
                **({"distil": distil.item()} if self.data.pairs is not None else {})}

    def distil(self, rng: np.random.Generator) -> torch.Tensor:
        """The pseudo-pairs' term: their inputs transferred with a mapped code of their style (a
        random ``z``, as a latent seed gives one), against their targets (zero without pairs)."""
        pairs, styles, targets = self.pair_windows(rng)
        if not len(pairs):
            return torch.zeros((), device=self.device)
        z = torch.from_numpy(rng.standard_normal((len(pairs), self.cfg.latent_dim)).astype(np.float32))
        codes = self.mapping_synced(z.to(self.device), F.one_hot(styles, len(self.data.styles)).float())
        return self.losses.distance(self.gen_synced(pairs, codes), targets)

    @torch.no_grad()
    def validate(self, model: Generator | None = None) -> dict[str, float]:
        """On fixed val windows with the weight averages (or ``model``): the identity reconstruction
        with the style encoder's own code, the style encoder's classification accuracy, and how
        often it recognises the target style in transfers by latent codes, and how far apart two
        seeds' poses are against two styles' (pelvis-relative joint distance)."""
        gen = model or self.gen_ema
        encoder = self.encoder_ema if model is None else self.encoder
        mapping = self.mapping_ema if model is None else self.mapping
        x, style, _ = self.val_windows
        codes, logits = encoder(x)
        real = self.losses.views(x[..., : gen.cfg.n_out])
        rec = self.losses.reconstruction(self.losses.views(gen(x, pick(codes, style))), real)
        z = torch.from_numpy(np.random.default_rng([self.cfg.seed, 5]).standard_normal(
            (len(style), self.cfg.latent_dim)).astype(np.float32)).to(self.device)
        s_trg = mapping(z, F.one_hot(self.val_targets, len(self.data.styles)).float())
        out = gen(x, s_trg)
        fake, _ = self.full(out, x[..., self.losses.contact_cols])
        transferred = encoder(fake)[1].argmax(-1)
        # diversity: outputs under a second seed, against outputs under another target style
        z2 = torch.from_numpy(np.random.default_rng([self.cfg.seed, 6]).standard_normal(
            z.shape).astype(np.float32)).to(self.device)
        other = (self.val_targets + 1) % len(self.data.styles)
        seeds = gen(x, mapping(z2, F.one_hot(self.val_targets, len(self.data.styles)).float()))
        styles = gen(x, mapping(z, F.one_hot(other, len(self.data.styles)).float()))
        base = pose(self.losses.views(out)["pos"])
        between_seeds, between_styles = ((pose(self.losses.views(o)["pos"]) - base).norm(dim=-1).mean()
                                         for o in (seeds, styles))
        return {**val_scores(rec),
                "val_style_acc": round(float((logits.argmax(-1) == style).float().mean()), 4),
                "val_transfer_style_acc": round(float((transferred == self.val_targets).float().mean()), 4),
                "val_seed_vs_style": round((between_seeds / between_styles.clamp(min=1e-8)).item(), 4)}


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "",
          log_every: int = 25, val_every: int = 500, init_from: int | None = None, device: str | None = None,
          licence: str | None = None) -> dict | None:
    """Train (resuming when asked; a new run with ``init_from`` continues that seed's run under
    this config) on ``device`` (default: the best there is; under ``torchrun``, in every process),
    export the weight averages to ``out_dir``; returns the card (None in the processes other than
    rank 0, which export nothing)."""
    def continue_other_run(trainer: Trainer) -> None:
        if init_from is not None and trainer.state["iteration"] == 0:
            trainer.initialise(Trainer.folder(checkpoints, init_from, cfg.data) / "checkpoint.pt",
                               Trainer.NETWORK_SETTINGS)
            if not trainer.rank:
                print(f"continuing seed {init_from}'s run at iteration {trainer.state['iteration']}")

    fitted = fit_for_export(Trainer, cfg, data, checkpoints, threads, device, progress, resume, minutes,
                            iterations, log_every, val_every, command, licence, continue_other_run)
    if fitted is None:  # not rank 0
        return None
    trainer, data, record, probe = fitted
    info = {
        **record,
        **({"continued_from": trainer.state["init_from"]} if "init_from" in trainer.state else {}),
        "exported": f"exponential moving averages of the three networks' weights (decay {cfg.ema})",
        "differences_from_paper": [
            (f"widths {cfg.widths} instead of (64, 128, 256), {cfg.window}-frame windows at 30 fps, "
            f"a {cfg.mapping_hidden}-wide mapping network instead of 1024 (2-hour CPU budget)"),
            ("6D rotations, positions, velocities, root motion and foot contacts per joint node; the "
            "generator outputs the root's velocity, height and yaw rate too, as a change to the input"),
            ("style encoder and discriminator average over time (any clip length) instead of a "
            "convolution over the whole clip; the style encoder has a style classifier head"),
            ("losses: non-saturating adversarial with R1 (weight 1), foot-contact loss, cycle and "
            "identity measured by rotation angle, FK positions, velocities and root"),
            f"Adam betas {cfg.betas}, learning rate {cfg.lr} (mapping {cfg.lr_mapping}), batch {cfg.batch}",
        ],
    }
    return write_model(trainer.gen_ema.cpu(), trainer.mapping_ema.cpu(), trainer.encoder_ema.cpu(),
                       out_dir / f"{NAME}.onnx", info, probe)


