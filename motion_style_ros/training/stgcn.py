"""ST-GCN stylizer training (Park et al. 2021) on Bandai Namco takes, ONNX export, model card.

Each iteration draws windows of real train takes with a random other target style, and a target
style code either from the mapping network (a random ``z``; even iterations) or from the style
encoder on a real window of the target style (odd iterations), as the paper alternates them.
The discriminator learns real vs transferred per style (non-saturating loss, R1 penalty on real
windows); the generator, mapping network and style encoder learn from the adversarial,
style-reconstruction, diversity-sensitive, cycle and identity losses, plus two additions: a
style classifier head on the style encoder (real windows' labels, so a reference clip of unknown
style picks its head) and a foot-contact loss (feet the input holds still stay still). Cycle and
identity use the recurrent trainer's reconstruction terms (rotation angle, FK positions and
velocities, root). The weight averages of the three networks are exported. The evaluation
judges in ``models/`` are never used here.
"""

from __future__ import annotations

import copy
import json
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from motion_style_ros.core.features import FEATURE_VERSION, feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.models.stgcn import (
    Discriminator,
    Generator,
    MappingNetwork,
    StgcnConfig,
    StyleEncoder,
    pick,
)
from motion_style_ros.training.judges import ATTRIBUTION
from motion_style_ros.training.data import NEUTRAL, Clips, Data, load_for, normalisation, recipe, windows
from motion_style_ros.training.recurrent import CHECKPOINTS, FPS, OPSET, Losses
from motion_style_ros.training.recurrent import (
    Trainer as RecurrentTrainer,
)

NAME = "stgcn"
_LAYOUT = feature_layout()
_FEET = [list(_LAYOUT.joints).index(j) for j in canonical().feet]


@dataclass(frozen=True)
class Config:
    """Everything that shapes the result; a checkpoint resumes only under the same config."""

    seed: int = 0
    # data (training.data.load_data): the shipped v1 model is dataset 2 with no augmentation
    datasets: tuple[int, ...] = (2,)
    speeds: tuple[float, ...] = ()
    balance: float = 0.0
    mirror: bool = False
    exclude: tuple[str, ...] = ()
    # networks (models.stgcn.StgcnConfig); the paper's widths are (64, 128, 256)
    window: int = 48
    widths: tuple[int, int, int] = (32, 64, 128)
    style_dim: int = 64
    latent_dim: int = 16
    mapping_hidden: int = 256
    # optimisation: Adam with StarGAN v2's betas (the paper's beta1 0.99 is too slow here)
    batch: int = 8
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
    # reconstruction terms inside cycle and identity (see training.recurrent.Losses)
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


def style_windows(clips: Clips, length: int, styles: np.ndarray, rng: np.random.Generator
                  ) -> torch.Tensor:
    """One random ``length``-frame window of a take of each requested style: ``(len(styles),
    length, F)``."""
    spans = np.array([max(len(f) - length + 1, 0) for f in clips.features], dtype=float)
    out = []
    for style in styles:
        p = spans * (clips.styles == style)
        if p.sum() == 0:
            raise MotionStyleError(f"no take of style {style} has the {length} frames a window needs")
        i = rng.choice(len(p), p=p / p.sum())
        s = rng.integers(0, int(spans[i]))
        out.append(clips.features[i][s : s + length])
    return torch.from_numpy(np.stack(out))


def _pose(pos: torch.Tensor) -> torch.Tensor:
    """Joint positions ``(..., J, 3)`` relative to the pelvis: the body's pose without its path."""
    return pos - pos[..., :1, :]


def _at(logits: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
    """Each row's logit of its style: ``(B, S)``, ``(B,)`` -> ``(B,)``."""
    return logits.gather(1, style[:, None])[:, 0]


class Trainer(RecurrentTrainer):
    """Generator, mapping network, style encoder, discriminator, the weight averages of the first
    three and the optimisers, with checkpoints in ``checkpoints/stgcn_<seed>/`` (``checkpoint.pt``,
    ``losses.jsonl``); the loop, checkpointing and resuming are the recurrent trainer's. Every
    iteration draws its data from a generator seeded by (seed, iteration)."""

    LABEL = "st-gcn"
    PARTS = ("gen", "mapping", "encoder", "dis", "gen_ema", "mapping_ema", "encoder_ema",
             "opt_g", "opt_d")

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True) -> None:
        self.cfg, self.data, self.progress = cfg, data, progress
        self.dir = checkpoints / f"{NAME}_{cfg.seed}"
        mean, std = normalisation(data.splits["train"], cfg.std_floor)
        self.losses = Losses(cfg, mean, std)
        net = cfg.networks(data.styles)
        torch.manual_seed(cfg.seed)
        self.gen = Generator(net, mean, std)
        self.mapping = MappingNetwork(net)
        self.encoder = StyleEncoder(net, mean, std)
        self.dis = Discriminator(net, mean, std)
        self.gen_ema, self.mapping_ema, self.encoder_ema = (
            copy.deepcopy(m).requires_grad_(False) for m in (self.gen, self.mapping, self.encoder))
        self.opt_g = torch.optim.Adam([
            {"params": [*self.gen.parameters(), *self.encoder.parameters()]},
            {"params": self.mapping.parameters(), "lr": cfg.lr_mapping}], lr=cfg.lr, betas=cfg.betas)
        self.opt_d = torch.optim.Adam(self.dis.parameters(), lr=cfg.lr, betas=cfg.betas)
        self.state = {"iteration": 0, "train_seconds": 0.0, "val": []}
        self.content_info = None
        val_rng = np.random.default_rng([cfg.seed, 3])
        self.val_windows = windows(data.splits["val"], cfg.window, 64, val_rng)
        self.val_targets = (self.val_windows[1] + torch.from_numpy(
            val_rng.integers(1, len(data.styles), 64))) % len(data.styles)
        self.in_std = torch.as_tensor(std, dtype=torch.float32)
        self.out_std = torch.as_tensor(std[: net.n_out], dtype=torch.float32)

    NETWORK_SETTINGS = ("datasets", "window", "widths", "style_dim", "latent_dim", "mapping_hidden",
                        "std_floor")

    def initialise(self, checkpoint: Path) -> None:
        """Continue another run (its weights, optimiser states, iteration count and time) under this
        run's loss settings; the networks and the data must be the same."""
        if not checkpoint.exists():
            raise MotionStyleError(f"{checkpoint}: no checkpoint to start from")
        saved = torch.load(checkpoint, weights_only=False)
        mine = self._settings()
        if ([saved["config"].get(k) for k in self.NETWORK_SETTINGS]
                != [mine["config"][k] for k in self.NETWORK_SETTINGS]
                or (saved["styles"], saved["contents"]) != (mine["styles"], mine["contents"])):
            raise MotionStyleError(f"{checkpoint} has other networks or data than this run "
                                   f"({', '.join(self.NETWORK_SETTINGS)}, styles and contents must match)")
        for name in self.PARTS:
            getattr(self, name).load_state_dict(saved[name])
        self.state = {**saved["state"], "init_from": {
            "checkpoint": str(checkpoint), "iteration": saved["state"]["iteration"],
            "train_seconds": round(saved["state"]["train_seconds"], 1), "config": saved["config"]}}

    @property
    def model(self) -> Generator:
        """The generator (the recurrent loop calls ``model.train()``)."""
        return self.gen

    def full(self, frames: torch.Tensor, contacts: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """encode() features ``(B, T, 260)`` of generated ``[root | rot6d]`` frames (FK positions
        and velocities; frame 0's velocity repeats frame 1's; contacts given), and their views."""
        views = self.losses.views(frames)
        vel = torch.cat([views["vel"][:, :1], views["vel"]], dim=1)
        return torch.cat([frames, views["pos"].flatten(-2), vel.flatten(-2), contacts], dim=-1), views

    def target_codes(self, iteration: int, target: torch.Tensor, rng: np.random.Generator,
                     mapping: MappingNetwork, encoder: StyleEncoder) -> tuple[torch.Tensor, torch.Tensor]:
        """Two target style codes per row: from noise (even iterations) or from real windows of the
        target style (odd iterations)."""
        if iteration % 2 == 0:
            z = torch.from_numpy(rng.standard_normal((2, len(target), self.cfg.latent_dim)).astype(np.float32))
            onehot = F.one_hot(target, len(self.data.styles)).float()
            return mapping(z[0], onehot), mapping(z[1], onehot)
        refs = [style_windows(self.data.splits["train"], self.cfg.window, target.numpy(), rng)
                for _ in range(2)]
        return pick(encoder(refs[0])[0], target), pick(encoder(refs[1])[0], target)

    def step(self, iteration: int) -> dict[str, float]:
        """One discriminator and one generator update; returns the loss terms."""
        cfg, n_styles = self.cfg, len(self.data.styles)
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, _ = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        target = (style + torch.from_numpy(rng.integers(1, n_styles, cfg.batch))) % n_styles
        contacts = x[..., _LAYOUT.slices["contact"]]
        code_rng = np.random.default_rng([cfg.seed, 4, iteration])
        s_trg, s_trg2 = self.target_codes(iteration, target, code_rng, self.mapping, self.encoder)

        # discriminator: real windows of their own style vs transfers to the target style; the R1
        # penalty every r1_every iterations with that much more weight (lazy regularisation)
        self.dis.requires_grad_(True)
        with torch.no_grad():
            fake, _ = self.full(self.gen(x, s_trg), contacts)
        lazy = iteration % cfg.r1_every == 0
        x_real = x.clone().requires_grad_(lazy)
        d_real = _at(self.dis(x_real), style)
        r1 = torch.zeros(())
        if lazy:
            (grad,) = torch.autograd.grad(d_real.sum(), x_real, create_graph=True)
            r1 = 0.5 * (grad * self.in_std).pow(2).sum(dim=(1, 2)).mean()  # w.r.t. normalised input
        d_fake = _at(self.dis(fake), target)
        critic = F.softplus(-d_real).mean() + F.softplus(d_fake).mean()
        self.opt_d.zero_grad()
        (critic + cfg.w_r1 * cfg.r1_every * r1).backward()
        self.opt_d.step()

        # generator, mapping network, style encoder
        self.dis.requires_grad_(False)
        out = self.gen(x, s_trg)
        fake, fake_views = self.full(out, contacts)
        adv = F.softplus(-_at(self.dis(fake), target)).mean()
        sty = (s_trg - pick(self.encoder(fake)[0], target)).abs().mean()
        with torch.no_grad():
            out2 = self.gen(x, s_trg2)
        if cfg.ds_cap is None:
            ds = ((out - out2) / self.out_std).abs().mean()
        else:  # per window: mean joint distance of the two poses, up to the cap
            apart = (_pose(fake_views["pos"]) - _pose(self.losses.views(out2)["pos"])).norm(dim=-1)
            ds = apart.mean(dim=(1, 2)).clamp(max=cfg.ds_cap).mean() / self.losses.pos_scale
        codes, logits = self.encoder(x)
        s_src = pick(codes, style)
        cls = F.cross_entropy(logits, style)
        real = self.losses.views(x[..., : self.gen.cfg.n_out])
        cyc = sum(self.losses.reconstruction(self.losses.views(self.gen(fake, s_src)), real).values())
        idt = sum(self.losses.reconstruction(self.losses.views(self.gen(x, s_src)), real).values())
        # feet the input holds still (contact at this frame and the one before) stay still
        still = (contacts[:, 1:] * contacts[:, :-1])[..., None]
        foot_vel = fake_views["vel"][:, :, _FEET]
        foot = (still * foot_vel.pow(2)).sum() / still.sum().clamp(min=1.0) / self.losses.vel_scale ** 2
        w_ds = cfg.w_ds * max(0.0, 1.0 - iteration / cfg.ds_iterations)
        total = (cfg.w_adv * adv + cfg.w_sty * sty - w_ds * ds + cfg.w_cyc * cyc + cfg.w_id * idt
                 + cfg.w_cls * cls + cfg.w_foot * foot)
        self.opt_g.zero_grad()
        total.backward()
        self.opt_g.step()
        with torch.no_grad():
            for avg, live in ((self.gen_ema, self.gen), (self.mapping_ema, self.mapping),
                              (self.encoder_ema, self.encoder)):
                for p_avg, p in zip(avg.parameters(), live.parameters()):
                    p_avg.lerp_(p, 1 - cfg.ema)
        return {"adv": adv.item(), "critic": critic.item(), "r1": r1.item(), "sty": sty.item(),
                "ds": ds.item(), "cyc": cyc.item(), "id": idt.item(), "cls": cls.item(),
                "foot": foot.item(), "rec": (cyc + idt).item()}

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
            (len(style), self.cfg.latent_dim)).astype(np.float32))
        s_trg = mapping(z, F.one_hot(self.val_targets, len(self.data.styles)).float())
        out = gen(x, s_trg)
        fake, _ = self.full(out, x[..., _LAYOUT.slices["contact"]])
        transferred = encoder(fake)[1].argmax(-1)
        # diversity: outputs under a second seed, against outputs under another target style
        z2 = torch.from_numpy(np.random.default_rng([self.cfg.seed, 6]).standard_normal(
            z.shape).astype(np.float32))
        other = (self.val_targets + 1) % len(self.data.styles)
        seeds = gen(x, mapping(z2, F.one_hot(self.val_targets, len(self.data.styles)).float()))
        styles = gen(x, mapping(z, F.one_hot(other, len(self.data.styles)).float()))
        pose, (between_seeds, between_styles) = _pose(self.losses.views(out)["pos"]), (
            (_pose(self.losses.views(o)["pos"]) - pose).norm(dim=-1).mean() for o in (seeds, styles))
        return {"val_rec": round(sum(rec.values()).item(), 5),
                "val_rot_deg": round(float(np.degrees(np.sqrt(rec["rot"].item()))), 3),
                "val_style_acc": round(float((logits.argmax(-1) == style).float().mean()), 4),
                "val_transfer_style_acc": round(float((transferred == self.val_targets).float().mean()), 4),
                "val_seed_vs_style": round((between_seeds / between_styles.clamp(min=1e-8)).item(), 4)}


# --- export --------------------------------------------------------------------------------------


def _export(module: torch.nn.Module, example: tuple, path: Path, inputs: list[str], outputs: list[str],
            dynamic: dict[str, dict[int, str]]) -> None:
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one (needs onnxscript).
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        # instance norm always normalises by the input's own statistics: "train=True" is right
        warnings.filterwarnings("ignore", message="ONNX export mode is set to TrainingMode.EVAL")
        torch.onnx.export(module.eval(), example, str(path), input_names=inputs, output_names=outputs,
                          dynamic_axes=dynamic, opset_version=OPSET, dynamo=False)


def companions(path: Path) -> dict[str, Path]:
    """The mapping network and style encoder files beside the generator at ``path``."""
    return {"mapping": path.with_name(f"{path.stem}_mapping.onnx"),
            "style_encoder": path.with_name(f"{path.stem}_style_encoder.onnx")}


def export_onnx(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path) -> None:
    """The generator at ``path`` and its two companions (:func:`companions`), opset 17, batch and
    time dynamic."""
    cfg = gen.cfg
    b, t = 2, cfg.window
    x = torch.zeros(b, t, cfg.n_features)
    _export(gen, (x, torch.zeros(b, cfg.style_dim)), path, ["features", "code"], ["output"],
            {"features": {0: "batch", 1: "frames"}, "code": {0: "batch"}, "output": {0: "batch", 1: "frames"}})
    files = companions(path)
    _export(mapping, (torch.zeros(b, cfg.latent_dim), torch.eye(len(cfg.styles))[[0] * b]),
            files["mapping"], ["z", "style"], ["code"], {n: {0: "batch"} for n in ("z", "style", "code")})
    _export(encoder, (x,), files["style_encoder"], ["features"], ["codes", "logits"],
            {"features": {0: "batch", 1: "frames"}, "codes": {0: "batch"}, "logits": {0: "batch"}})


def parity(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path,
           clip: np.ndarray) -> float:
    """Largest ONNX vs torch difference of the three networks on ``clip`` ``(T, F)`` (cut into
    windows; every style's latent code)."""
    from motion_style_ros.runtime.onnx_model import OnnxModel

    cfg = gen.cfg
    n = len(cfg.styles)
    t = len(clip) // cfg.window * cfg.window
    x = clip[:t].reshape(-1, cfg.window, clip.shape[-1]).astype(np.float32)
    z = np.random.default_rng(0).standard_normal((n, cfg.latent_dim)).astype(np.float32)
    style = np.eye(n, dtype=np.float32)
    files = companions(path)
    codes = OnnxModel(files["mapping"]).run(z=z, style=style)["code"]
    xs = np.repeat(x, n, axis=0)
    cs = np.tile(codes, (len(x), 1))
    out = OnnxModel(path).run(features=xs, code=cs)["output"]
    enc = OnnxModel(files["style_encoder"]).run(features=x)
    with torch.no_grad():
        expected = [mapping(torch.from_numpy(z), torch.from_numpy(style)).numpy(),
                    gen(torch.from_numpy(xs), torch.from_numpy(cs)).numpy(),
                    *(a.numpy() for a in encoder(torch.from_numpy(x)))]
    got = [codes, out, enc["codes"], enc["logits"]]
    return float(max(np.abs(a - b).max() for a, b in zip(got, expected)))


def card(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, training: dict, path: Path
         ) -> dict:
    """The model card (``models/<name>.json``); ``metrics`` is filled later by eval/bench."""
    cfg = gen.cfg
    n_styles = len(cfg.styles)
    return {
        "name": path.stem,
        "kind": "windowed",
        "task": "motion style transfer over windows of frames, streamed by overlap-add; style codes "
                "from a latent seed (mapping network) or a reference clip (style encoder)",
        "styles": list(cfg.styles),
        "neutral_style": NEUTRAL if NEUTRAL in cfg.styles else cfg.styles[0],
        "fps": FPS,
        "skeleton": "canonical",
        "feature_version": FEATURE_VERSION,
        "feature_layout": {k: [s.start, s.stop] for k, s in _LAYOUT.slices.items()},
        "window": cfg.window,
        "frames_multiple": 4,
        "style_dim": cfg.style_dim,
        "latent_dim": cfg.latent_dim,
        "opset": OPSET,
        "files": {k: p.name for k, p in companions(path).items()},
        "inputs": {
            "features": f"(B, T, {cfg.n_features}) float32: motion_style_ros.core.features.encode() of "
                        f"T frames, raw (normalised inside); T a multiple of 4, trained at {cfg.window}",
            "code": f"(B, {cfg.style_dim}) float32 style code (mapping network or style encoder; "
                    "codes may be interpolated)",
        },
        "outputs": {
            "output": f"(B, T, {cfg.n_out}) float32: the stylized frames as encode()'s [root (4) | "
                      f"rot6d ({cfg.n_out - 4})] blocks, raw units, 6D rotations orthonormalised",
        },
        "mapping": {"inputs": {"z": f"(B, {cfg.latent_dim}) float32 standard normal noise",
                               "style": f"(B, {n_styles}) float32 one-hot over 'styles'"},
                    "outputs": {"code": f"(B, {cfg.style_dim}) float32"}},
        "style_encoder": {"inputs": {"features": f"(B, T, {cfg.n_features}) float32 raw, T >= "
                                                 f"{cfg.window} and a multiple of 4"},
                          "outputs": {"codes": f"(B, {n_styles}, {cfg.style_dim}) float32: the clip's "
                                               "code under each style's head",
                                      "logits": f"(B, {n_styles}) float32: which style the clip is"}},
        "architecture": {
            **{k: v for k, v in asdict(cfg).items() if k != "styles"},
            "parameters": {name: int(sum(p.numel() for p in m.parameters()))
                           for name, m in (("generator", gen), ("mapping", mapping),
                                           ("style_encoder", encoder))},
        },
        "training": training,
        "licence": "CC BY-NC 4.0 (inherited from the training data): non-commercial use only",
        "attribution": ATTRIBUTION,
        "metrics": {},
    }


def write_model(gen: Generator, mapping: MappingNetwork, encoder: StyleEncoder, path: Path,
                training: dict, probe: np.ndarray | None = None) -> dict:
    """The three ONNX graphs and the card beside the generator at ``path``; returns the card.
    With a ``probe`` clip ``(T, F)``, the card records the ONNX vs torch difference on it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    export_onnx(gen, mapping, encoder, path)
    if probe is not None:
        training = {**training, "onnx_torch_max_abs_diff": parity(gen, mapping, encoder, path, probe),
                    "parity_probe_frames": len(probe)}
    info = card(gen, mapping, encoder, training, path)
    path.with_suffix(".json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "",
          log_every: int = 25, val_every: int = 500, init_from: int | None = None) -> dict:
    """Train (resuming when asked; a new run with ``init_from`` continues that seed's run under
    this config), export the weight averages to ``out_dir``; returns the card."""
    torch.set_num_threads(threads)
    started = time.perf_counter()
    data = data or load_for(cfg, progress)
    trainer = Trainer.started(cfg, data, checkpoints, progress, resume)
    if init_from is not None and trainer.state["iteration"] == 0:
        trainer.initialise(checkpoints / f"{NAME}_{init_from}" / "checkpoint.pt")
        print(f"continuing seed {init_from}'s run at iteration {trainer.state['iteration']}")
    setup_s = time.perf_counter() - started
    trainer.run(minutes, iterations, log_every=log_every, val_every=val_every)
    probe = max(data.splits["val"].features, key=len)
    info = {
        **recipe(cfg),
        "clips": {k: len(c.features) for k, c in data.splits.items()},
        "command": command,
        "seed": cfg.seed,
        "config": asdict(cfg),
        "wall_time_s": round(trainer.state["train_seconds"] + setup_s, 1),
        "history": trainer.summary(),
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
    return write_model(trainer.gen_ema, trainer.mapping_ema, trainer.encoder_ema, out_dir / f"{NAME}.onnx",
                       info, probe)


def export_random_model(path: Path, styles: list[str], seed: int = 0) -> None:
    """Untrained tiny networks with the real interface (identity normalisation), for runtime tests
    that must not depend on the shipped model. The generator's last layer is randomised so that
    its output depends on the code."""
    from motion_style_ros.models.stgcn import tiny

    cfg = tiny(tuple(styles))
    torch.manual_seed(seed)
    mean, std = np.zeros(cfg.n_features), np.ones(cfg.n_features)
    gen = Generator(cfg, mean, std)
    with torch.no_grad():
        gen.last.weight.normal_(0.0, 0.05)
    write_model(gen, MappingNetwork(cfg), StyleEncoder(cfg, mean, std), Path(path),
                {"data": "none: random weights", "seed": seed})
