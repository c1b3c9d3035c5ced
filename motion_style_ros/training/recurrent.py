"""Style-ERD training on Bandai Namco takes, ONNX export of the streaming step, model card.

One run: (1) the content network (the perceptual loss's feature extractor) is trained on content
labels, or loaded from the checkpoint folder; (2) the generator and the FT-Att discriminator train
adversarially on windows of real takes; (3) the exponential moving average of the generator's
weights is exported. Each window is used twice per iteration: with its own style as the target
(reconstruction loss) and with a random other style (adversarial and perceptual losses). The
evaluation judges in ``models/`` are never used here.
"""

from __future__ import annotations

import copy
import json
import sys
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from motion_style_ros.core.features import FEATURE_VERSION, encode, feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.models.style_erd import (
    OUT_ROOT,
    ContentNet,
    ErdConfig,
    FTAttDiscriminator,
    StepGraph,
    StyleERD,
    tiny,
)
from motion_style_ros.training.data import NEUTRAL, Clips, Data, load_for, normalisation, recipe, windows
from motion_style_ros.training.judges import ATTRIBUTION

FPS = 30.0
NAME = "style_erd"
OPSET = 17
CHECKPOINTS = Path.home() / ".cache" / "motion_style_ros" / "checkpoints"

@dataclass(frozen=True)
class Config:
    """Everything that shapes the result; a checkpoint resumes only under the same config."""

    seed: int = 0
    datasets: tuple[int, ...] = (2,)
    # data: every train take can also be used played slower and faster (other performers walk at
    # other paces); windows are drawn with weight frames / style_frames ** balance, so that
    # dataset-1's styles (one take per content) come up more often than their share of frames.
    # The shipped model uses neither; the 22-style run of the models-v2 issue used (0.8, 1.25) and 0.5.
    speeds: tuple[float, ...] = ()
    balance: float = 0.0
    mirror: bool = False  # also every train take mirrored left-right (training.data.load_data)
    exclude: tuple[str, ...] = ()  # styles left out (to enrol them later through a style bank)
    # generator (see models.style_erd.ErdConfig). Shallower and wider than the paper's 6 + 4 LSTM
    # layers of width 32: on 2 CPU cores the deep stacks had barely started to reconstruct after
    # 300 iterations while this one was within a few centimetres (pos loss 0.08 vs 0.94).
    encoder: tuple[int, ...] = (128,)
    latent: int = 64
    neutral_layers: int = 2
    style_layers: int = 2
    decoder: tuple[int, ...] = (128, 128)
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
    # the adversarial and perceptual weights ramp up linearly over the first iterations, so the
    # generator reconstructs plausible motion before the critics push it around
    warmup: int = 2000
    std_floor: float = 0.05
    # critics
    dis_widths: tuple[int, ...] = (128, 96, 64)
    dis_features: int = 16
    content_widths: tuple[int, ...] = (128, 96, 64)
    content_iterations: int = 1500
    content_batch: int = 32
    content_lr: float = 1e-3

    @property
    def window(self) -> int:
        return self.crops * self.crop_frames + 1

    def erd(self, styles: tuple[str, ...]) -> ErdConfig:
        return ErdConfig(styles, NEUTRAL, encoder=self.encoder, latent=self.latent,
                         neutral_layers=self.neutral_layers, style_layers=self.style_layers,
                         decoder=self.decoder)


def tiny_config(**changes) -> Config:
    """A small, fast configuration with the real data path (tests)."""
    return replace(Config(encoder=(16,), latent=8, neutral_layers=2, style_layers=1, decoder=(16,),
                          batch=4, crops=1, crop_frames=12, dis_widths=(16,), dis_features=4,
                          content_widths=(16,), content_iterations=5, content_batch=4, warmup=10),
                   **changes)


# --- kinematics and losses -----------------------------------------------------------------------


class Kinematics(nn.Module):
    """The ``pos`` and ``vel`` feature blocks from ``[root | rot6d]`` frames, differentiably: forward
    kinematics of the canonical skeleton in the facing frame, and velocities as the root velocity
    plus the change of facing-relative positions (the maths of ``core.features.encode``)."""

    def __init__(self) -> None:
        super().__init__()
        sk = canonical()
        joints = list(feature_layout(sk).joints)
        self.parents = [joints.index(sk.parents[j]) if k else -1 for k, j in enumerate(joints)]
        self.register_buffer("offsets", torch.tensor(sk.offsets[joints], dtype=torch.float32))

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(B, T, 130)`` -> local rotation matrices ``(B, T, J, 3, 3)``, positions ``(B, T, J, 3)``,
        velocities of frames 1.. ``(B, T-1, J, 3)``."""
        root = frames[..., :OUT_ROOT]
        d6 = frames[..., OUT_ROOT:].unflatten(-1, (-1, 6))
        x, y = d6[..., :3], d6[..., 3:]
        local = torch.stack([x, y, torch.linalg.cross(x, y)], dim=-1)
        zero = torch.zeros_like(root[..., :1])
        g_rot = [local[..., 0, :, :]]
        g_pos = [torch.cat([zero, root[..., 2:3], zero], dim=-1)]
        for k, p in enumerate(self.parents[1:], start=1):
            g_pos.append(g_pos[p] + g_rot[p] @ self.offsets[k])
            g_rot.append(g_rot[p] @ local[..., k, :, :])
        pos = torch.stack(g_pos, dim=-2)
        # Previous positions turned into the current facing frame (a turn by -yaw rate / fps).
        turn = -root[..., 1:, 3:4] / FPS
        cos, sin = torch.cos(turn), torch.sin(turn)
        prev = pos[..., :-1, :, :]
        prev = torch.stack([cos * prev[..., 0] + sin * prev[..., 2], prev[..., 1],
                            cos * prev[..., 2] - sin * prev[..., 0]], dim=-1)
        ground = torch.stack([root[..., 1:, 0], torch.zeros_like(root[..., 1:, 0]), root[..., 1:, 1]], -1)
        vel = ground[..., None, :] + (pos[..., 1:, :, :] - prev) * FPS
        return local, pos, vel


def rotation_angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle (rad) between rotation matrices ``(..., 3, 3)``; the clamp keeps acos' gradient finite."""
    cos = ((a * b).sum(dim=(-2, -1)) - 1) / 2
    return torch.acos(cos.clamp(-1 + 1e-6, 1 - 1e-6))


class Losses(nn.Module):
    """Per-term losses in comparable units, from the train-set statistics of the feature blocks."""

    def __init__(self, cfg: Config, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.cfg = cfg
        self.kinematics = Kinematics()
        s = feature_layout().slices
        self.pos_scale, self.vel_scale = (float(np.sqrt(np.mean(std[s[b]] ** 2))) for b in ("pos", "vel"))
        self.register_buffer("root_std", torch.as_tensor(std[s["root"]], dtype=torch.float32))
        # critic inputs: normalised rot6d, pos and vel blocks (content) or pos and vel (discriminator)
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.rot_cols = slice(s["rot6d"].start, s["rot6d"].stop)
        self.pv_cols = slice(s["pos"].start, s["vel"].stop)
        self.contact_cols = s["contact"]
        sk = canonical()
        joints = list(feature_layout(sk).joints)
        self.feet = [joints.index(f) for f in sk.feet]  # the contact block's order

    def views(self, frames: torch.Tensor) -> dict[str, torch.Tensor]:
        """Rotations, positions, velocities of ``[root | rot6d]`` frames, and the critics' inputs
        (frames 1..: the first has no velocity)."""
        local, pos, vel = self.kinematics(frames)
        pv = torch.cat([pos[:, 1:].flatten(-2), vel.flatten(-2)], dim=-1)
        pv = (pv - self.mean[self.pv_cols]) / self.std[self.pv_cols]
        rot6d = (frames[:, 1:, OUT_ROOT:] - self.mean[self.rot_cols]) / self.std[self.rot_cols]
        return {"root": frames[..., :OUT_ROOT], "local": local, "pos": pos, "vel": vel,
                "pv": pv, "content": torch.cat([rot6d, pv], dim=-1)}

    def reconstruction(self, out: dict[str, torch.Tensor], real: dict[str, torch.Tensor]
                       ) -> dict[str, torch.Tensor]:
        c = self.cfg
        return {
            "rot": rotation_angle(out["local"], real["local"]).pow(2).mean(),
            "pos": c.w_pos * ((out["pos"] - real["pos"]) / self.pos_scale).pow(2).sum(-1).mean(),
            "vel": c.w_vel * ((out["vel"] - real["vel"]) / self.vel_scale).pow(2).sum(-1).mean(),
            "root": c.w_root * ((out["root"] - real["root"]) / self.root_std).pow(2).mean(),
        }

    def foot(self, out: dict[str, torch.Tensor], x: torch.Tensor) -> torch.Tensor:
        """Squared velocity (train-std units) of the foot joints the input ``x`` (features) holds
        in contact, per frame 1.. (the first has no velocity)."""
        contact = x[:, 1:, self.contact_cols]
        speed = (out["vel"][:, :, self.feet] / self.vel_scale).pow(2).sum(-1)
        return (contact * speed).mean()

    def crops(self, pv: torch.Tensor) -> torch.Tensor:
        """``(B, crops * crop_frames, C)`` -> ``(B * crops, crop_frames, C)``."""
        return pv.reshape(-1, self.cfg.crop_frames, pv.shape[-1])


# --- training ------------------------------------------------------------------------------------

_MININTERVAL = 0.1 if sys.stderr.isatty() else 30.0  # progress lines in a log file: one per 30 s
_FRAME = feature_layout().slices["rot6d"].stop  # encode()'s [root | rot6d] blocks lead its layout


def _frames(x: torch.Tensor) -> torch.Tensor:
    """The ``[root | rot6d]`` part of encode() features: what the generator outputs."""
    return x[..., :_FRAME]


def _onehot(index: torch.Tensor, n: int, repeat: int = 1) -> torch.Tensor:
    return F.one_hot(index, n).float().repeat_interleave(repeat, dim=0)


def _content_settings(cfg: Config) -> dict:
    names = ("seed", "datasets", "crops", "crop_frames", "std_floor", "content_widths",
             "content_iterations", "content_batch", "content_lr")
    return {k: getattr(cfg, k) for k in names}


def content_network(cfg: Config, data: Data, losses: Losses, path: Path, progress: bool = True
                    ) -> tuple[ContentNet, dict]:
    """The frozen content network of the perceptual loss: loaded from ``path``, or trained on the
    train takes' content labels and saved there. Returns it and its val window accuracy."""
    channels = losses.rot_cols.stop - losses.rot_cols.start + losses.pv_cols.stop - losses.pv_cols.start
    torch.manual_seed(cfg.seed)
    net = ContentNet(channels, len(data.contents), cfg.content_widths)
    if path.exists():
        saved = torch.load(path, weights_only=False)
        if saved["settings"] == _content_settings(cfg) and saved["contents"] == list(data.contents):
            net.load_state_dict(saved["model"])
            return net.requires_grad_(False).eval(), saved["info"]
    optimizer = torch.optim.Adam(net.parameters(), lr=cfg.content_lr)
    bar = tqdm(range(cfg.content_iterations), desc="content network", disable=not progress,
               mininterval=_MININTERVAL)
    for it in bar:
        x, _, content = windows(data.splits["train"], cfg.window, cfg.content_batch,
                                np.random.default_rng([cfg.seed, 1, it]))
        loss = F.cross_entropy(net(losses.views(_frames(x))["content"])[0], content)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        bar.set_postfix(loss=f"{loss.item():.3f}", refresh=False)
    net.requires_grad_(False).eval()
    x, _, content = windows(data.splits["val"], cfg.window, 256, np.random.default_rng([cfg.seed, 2]))
    with torch.no_grad():
        logits, _ = net(losses.views(_frames(x))["content"])
    info = {"val_window_accuracy": round(float((logits.argmax(-1) == content).float().mean()), 4),
            "window_frames": cfg.window, "iterations": cfg.content_iterations}
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"settings": _content_settings(cfg), "contents": list(data.contents),
                "model": net.state_dict(), "info": info}, path)
    return net, info


class Trainer:
    """Generator, discriminator, their optimisers and the generator's weight average, with
    checkpoints in ``checkpoints/recurrent_<seed>/`` (``checkpoint.pt``, ``content_net.pt``,
    ``losses.jsonl``). Every iteration draws its windows from a generator seeded by (seed,
    iteration), so a resumed run repeats what an uninterrupted one would have done."""

    LABEL = "style-erd"  # the progress bar's
    PARTS = ("model", "ema", "dis", "opt_g", "opt_d")  # what a checkpoint holds besides the state

    def __init__(self, cfg: Config, data: Data, checkpoints: Path = CHECKPOINTS,
                 progress: bool = True) -> None:
        self.cfg, self.data, self.progress = cfg, data, progress
        self.dir = checkpoints / f"recurrent_{cfg.seed}"
        mean, std = normalisation(data.splits["train"], cfg.std_floor)
        self.losses = Losses(cfg, mean, std)
        self.content, self.content_info = content_network(cfg, data, self.losses,
                                                          self.dir / "content_net.pt", progress)
        torch.manual_seed(cfg.seed)
        self.model = StyleERD(cfg.erd(data.styles), mean, std, mean[:_FRAME], std[:_FRAME])
        self.ema = copy.deepcopy(self.model).requires_grad_(False)
        self.dis = FTAttDiscriminator(self.losses.pv_cols.stop - self.losses.pv_cols.start,
                                      len(data.styles), len(data.contents), cfg.crop_frames,
                                      cfg.dis_widths, cfg.dis_features)
        self.opt_g = torch.optim.Adam(self.model.parameters(), lr=cfg.lr_gen)
        self.opt_d = torch.optim.Adam(self.dis.parameters(), lr=cfg.lr_dis)
        self.state = {"iteration": 0, "train_seconds": 0.0, "val": []}
        val_rng = np.random.default_rng([cfg.seed, 3])
        self.val_windows = windows(data.splits["val"], cfg.window, 128, val_rng)
        self.val_targets = (self.val_windows[1] + torch.from_numpy(
            val_rng.integers(1, len(data.styles), 128))) % len(data.styles)

    @property
    def checkpoint(self) -> Path:
        return self.dir / "checkpoint.pt"

    @property
    def log(self) -> Path:
        return self.dir / "losses.jsonl"

    def _settings(self) -> dict:
        return {"config": asdict(self.cfg), "styles": list(self.data.styles),
                "contents": list(self.data.contents)}

    def save(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        tmp = self.checkpoint.with_suffix(".tmp")
        torch.save({**self._settings(), **{name: getattr(self, name).state_dict() for name in self.PARTS},
                    "state": self.state}, tmp)
        tmp.replace(self.checkpoint)

    def resume(self) -> bool:
        """Continue from the checkpoint if there is one; log lines written after it are dropped."""
        if not self.checkpoint.exists():
            return False
        saved = torch.load(self.checkpoint, weights_only=False)
        if {k: saved[k] for k in ("config", "styles", "contents")} != self._settings():
            raise MotionStyleError(
                f"{self.checkpoint} was made with other settings or data; train without --resume "
                "to start afresh, or use another --seed"
            )
        for name in self.PARTS:
            getattr(self, name).load_state_dict(saved[name])
        self.state = saved["state"]
        if self.log.exists():
            kept = [line for line in self.log.read_text().splitlines()
                    if json.loads(line)["iteration"] <= self.state["iteration"]]
            self.log.write_text("".join(line + "\n" for line in kept))
        return True

    @classmethod
    def started(cls, cfg, data: Data, checkpoints: Path, progress: bool, resume: bool) -> "Trainer":
        """A trainer continuing from its checkpoint (``resume`` and there is one) or afresh."""
        trainer = cls(cfg, data, checkpoints, progress)
        if resume and trainer.resume():
            print(f"resuming {trainer.checkpoint} at iteration {trainer.state['iteration']}")
        elif not resume:
            trainer.fresh_start()
        return trainer

    def fresh_start(self) -> None:
        """Forget an earlier run's checkpoint and log (the content network stays: it is keyed by
        its own settings)."""
        for path in (self.checkpoint, self.log):
            path.unlink(missing_ok=True)

    def step(self, iteration: int) -> dict[str, float]:
        """One discriminator and one generator update; returns the loss terms."""
        cfg, n_styles = self.cfg, len(self.data.styles)
        rng = np.random.default_rng([cfg.seed, 0, iteration])
        x, style, content = windows(self.data.splits["train"], cfg.window, cfg.batch, rng)
        other = (style + torch.from_numpy(rng.integers(1, n_styles, cfg.batch))) % n_styles
        out = self.losses.views(self.model.stylize(torch.cat([x, x]), torch.cat([style, other])))
        rec = {k: v[: cfg.batch] for k, v in out.items()}
        fake = {k: v[cfg.batch :] for k, v in out.items()}
        real = self.losses.views(_frames(x))
        labels_real = (_onehot(style, n_styles, cfg.crops), _onehot(content, len(self.data.contents), cfg.crops))
        labels_fake = (_onehot(other, n_styles, cfg.crops), labels_real[1])

        # critic: real -> 1, transferred -> -1, gradient penalty on real crops (LSGAN, paper eq. 5, 6)
        self.dis.requires_grad_(True)
        real_pv = self.losses.crops(real["pv"]).requires_grad_(True)
        d_real = self.dis(real_pv, *labels_real)
        (grad,) = torch.autograd.grad(d_real.sum(), real_pv, create_graph=True)
        gp = grad.pow(2).sum(dim=(1, 2)).mean()
        d_fake = self.dis(self.losses.crops(fake["pv"].detach()), *labels_fake)
        critic = (d_real - 1).pow(2).mean() + (d_fake + 1).pow(2).mean()
        self.opt_d.zero_grad()
        (critic + cfg.w_gp * gp).backward()
        self.opt_d.step()

        # generator: reconstruction + adversarial (D(fake) -> 0, eq. 4) + perceptual
        self.dis.requires_grad_(False)
        terms = self.losses.reconstruction(rec, real)
        adv = self.dis(self.losses.crops(fake["pv"]), *labels_fake).pow(2).mean()
        with torch.no_grad():
            _, target_maps = self.content(real["content"])
        _, maps = self.content(fake["content"])
        per = sum(F.mse_loss(a, b) for a, b in zip(maps, target_maps))
        foot = self.losses.foot(fake, x)
        ramp = min(1.0, (iteration + 1) / cfg.warmup) if cfg.warmup else 1.0
        total = sum(terms.values()) + ramp * (cfg.w_adv * adv + cfg.w_per * per + cfg.w_foot * foot)
        self.opt_g.zero_grad()
        total.backward()
        self.opt_g.step()
        with torch.no_grad():
            for p_avg, p in zip(self.ema.parameters(), self.model.parameters()):
                p_avg.lerp_(p, 1 - cfg.ema)
        return {**{k: v.item() for k, v in terms.items()}, "rec": sum(terms.values()).item(),
                "adv": adv.item(), "per": per.item(), "foot": foot.item(), "critic": critic.item(), "gp": gp.item()}

    @torch.no_grad()
    def validate(self, model: StyleERD | None = None) -> dict[str, float]:
        """Reconstruction loss of ``model`` (default: the weight average) on fixed val windows
        with their own style as the target, and how often our content network still recognises
        the content after transfer to another style."""
        model = model or self.ema
        x, style, content = self.val_windows
        real = self.losses.views(_frames(x))
        rec = self.losses.reconstruction(self.losses.views(model.stylize(x, style)), real)
        fake = self.losses.views(model.stylize(x, self.val_targets))
        logits, _ = self.content(fake["content"])
        return {"val_rec": round(sum(rec.values()).item(), 5),
                "val_rot_deg": round(float(np.degrees(np.sqrt(rec["rot"].item()))), 3),
                "val_transfer_content_acc": round(float((logits.argmax(-1) == content).float().mean()), 4)}

    def _append_log(self, entry: dict) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        with open(self.log, "a") as f:
            f.write(json.dumps(entry) + "\n")

    def run(self, minutes: float | None = None, iterations: int | None = None, log_every: int = 25,
            val_every: int = 500, checkpoint_minutes: float = 5.0) -> None:
        """Train until ``minutes`` of training (over all resumed runs) or ``iterations`` in total."""
        budget_s = float("inf") if minutes is None else 60.0 * minutes
        last_iteration = iterations if iterations is not None else 2**62
        state = self.state
        started = time.perf_counter()

        def spent() -> float:
            return state["train_seconds"] + time.perf_counter() - started

        last_save, recent = time.perf_counter(), []
        bar = tqdm(total=iterations, initial=state["iteration"], desc=self.LABEL, unit="it",
                   disable=not self.progress, mininterval=_MININTERVAL)
        while state["iteration"] < last_iteration and spent() < budget_s:
            self.model.train()
            recent.append(self.step(state["iteration"]))
            state["iteration"] += 1
            bar.update()
            if state["iteration"] % log_every == 0 or state["iteration"] == last_iteration:
                means = {k: round(float(np.mean([r[k] for r in recent])), 5) for k in recent[0]}
                self._append_log({"iteration": state["iteration"], "seconds": round(spent(), 1), **means})
                bar.set_postfix(rec=means["rec"], adv=means["adv"], critic=means["critic"],
                                left=f"{max(budget_s - spent(), 0) / 60:.0f}min" if minutes else None,
                                refresh=False)
                recent = []
            if state["iteration"] % val_every == 0:
                state["val"].append({"iteration": state["iteration"], **self.validate()})
                self._append_log({**state["val"][-1], "seconds": round(spent(), 1)})
            if time.perf_counter() - last_save > 60 * checkpoint_minutes:
                state["train_seconds"] = spent()
                started, last_save = time.perf_counter(), time.perf_counter()
                self.save()
        bar.close()
        if recent:
            means = {k: round(float(np.mean([r[k] for r in recent])), 5) for k in recent[0]}
            self._append_log({"iteration": state["iteration"], "seconds": round(spent(), 1), **means})
        if not state["val"] or state["val"][-1]["iteration"] != state["iteration"]:
            state["val"].append({"iteration": state["iteration"], **self.validate()})
            self._append_log({**state["val"][-1], "seconds": round(spent(), 1)})
        state["train_seconds"] = spent()
        self.save()

    def summary(self) -> dict:
        """Loss history for the model card: first and last logged train losses, val history."""
        train = [e for e in map(json.loads, self.log.read_text().splitlines()) if "rec" in e] \
            if self.log.exists() else []
        return {"iterations": self.state["iteration"],
                "train_seconds": round(self.state["train_seconds"], 1),
                "iterations_per_second": round(self.state["iteration"] / max(self.state["train_seconds"], 1e-9), 3),
                "first_logged": train[0] if train else None, "last_logged": train[-1] if train else None,
                "val": self.state["val"], "content_network": self.content_info}


def parity(model: StyleERD, onnx_path: Path, features: np.ndarray) -> float:
    """Largest difference between the ONNX graph stepped frame by frame (state carried) and the
    torch model run over the whole ``(T, F)`` clip, for each style as the target."""
    from motion_style_ros.runtime.onnx_model import OnnxModel

    session = OnnxModel(onnx_path).session
    n = len(model.cfg.styles)
    style = np.eye(n, dtype=np.float32)
    alpha = np.ones((n, 1), np.float32)
    x = np.repeat(features[None].astype(np.float32), n, axis=0)
    with torch.no_grad():
        expected, _ = model.eval()(torch.from_numpy(x), torch.from_numpy(style), torch.from_numpy(alpha))
    state = np.zeros((n, model.cfg.state_size), np.float32)
    worst = 0.0
    for t in range(len(features)):
        out, state = session.run(None, {"features": x[:, t], "style": style, "alpha": alpha,
                                        "state": state, "reset": np.full((n, 1), float(t == 0), np.float32)})
        worst = max(worst, float(np.abs(out - expected[:, t].numpy()).max()))
    return worst


def train(cfg: Config, out_dir: Path, minutes: float | None = None, iterations: int | None = None,
          resume: bool = False, checkpoints: Path = CHECKPOINTS, threads: int = 2,
          data: Data | None = None, progress: bool = True, command: str = "") -> dict:
    """Train (resuming when asked), export the weight-averaged generator to ``out_dir``; returns
    the model card."""
    torch.set_num_threads(threads)
    started = time.perf_counter()
    data = data or load_for(cfg, progress)
    trainer = Trainer.started(cfg, data, checkpoints, progress, resume)
    setup_s = time.perf_counter() - started
    trainer.run(minutes, iterations)
    onnx_path = out_dir / f"{NAME}.onnx"
    probe = max(data.splits["val"].features, key=len)
    info = {
        **recipe(cfg),
        "clips": {k: len(c.features) for k, c in data.splits.items()},
        "contents": list(data.contents),
        "command": command,
        "seed": cfg.seed,
        "config": asdict(cfg),
        "wall_time_s": round(trainer.state["train_seconds"] + setup_s, 1),
        "history": trainer.summary(),
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
    return write_model(trainer.ema, onnx_path, info, probe)


def export_onnx(model: StyleERD, path: Path) -> None:
    """The streaming step as ONNX (opset 17): recurrent state as explicit input and output."""
    cfg = model.cfg
    graph = StepGraph(model).eval()
    b = 2
    example = (
        torch.zeros(b, cfg.n_features),
        torch.eye(len(cfg.styles))[[0] * b],
        torch.ones(b, 1),
        torch.zeros(b, cfg.state_size),
        torch.ones(b, 1),
    )
    names = ["features", "style", "alpha", "state", "reset"]
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one (which needs
        # onnxscript); LSTMs with explicit state export the same either way.
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.filterwarnings("ignore", message="Exporting a model to ONNX with a batch_size")
        warnings.simplefilter("ignore", torch.jit.TracerWarning)  # nn.LSTM's shape checks
        torch.onnx.export(
            graph,
            example,
            str(path),
            input_names=names,
            output_names=["output", "state_out"],
            dynamic_axes={n: {0: "batch"} for n in [*names, "output", "state_out"]},
            opset_version=OPSET,
            dynamo=False,
        )


def card(model: StyleERD, training: dict) -> dict:
    """The model card (``models/<name>.json``); ``metrics`` is filled later by eval/bench."""
    cfg = model.cfg
    lay = feature_layout()
    n_out = cfg.n_out
    return {
        "name": NAME,
        "kind": "recurrent",
        "task": "online motion style transfer: one frame in, one stylized frame out, no lookahead",
        "styles": list(cfg.styles),
        "neutral_style": cfg.neutral,
        "fps": FPS,
        "skeleton": "canonical",
        "feature_version": FEATURE_VERSION,
        "feature_layout": {k: [s.start, s.stop] for k, s in lay.slices.items()},
        "state_size": cfg.state_size,
        "opset": OPSET,
        "inputs": {
            "features": f"(B, {cfg.n_features}) float32: motion_style_ros.core.features.encode() of the "
                        "current input frame, raw (normalised inside the graph)",
            "style": f"(B, {len(cfg.styles)}) float32 weights over 'styles' (one-hot or a mix, rows "
                     "sum to 1); every branch runs at every step, the weights only mix outputs",
            "alpha": "(B, 1) float32 in [0, 1]: scales the style residual and the decoder's style "
                     f"conditioning; 0 = the neutral branch alone (same as style '{cfg.neutral}')",
            "state": f"(B, {cfg.state_size}) float32: every LSTM h and c, flattened (ignored where reset=1)",
            "reset": "(B, 1) float32: where 1, the learned initial state replaces 'state' before "
                     "the step (first frame, after reset or a gap); it does not depend on 'style' "
                     "since every branch has its own",
        },
        "outputs": {
            "output": f"(B, {n_out}) float32: the stylized frame as encode()'s [root (4) | rot6d "
                      f"({n_out - 4})] blocks, raw units, 6D rotations orthonormalised",
            "state_out": f"(B, {cfg.state_size}) float32: the state to pass at the next frame",
        },
        "architecture": {
            **{k: v for k, v in asdict(cfg).items() if k != "styles"},
            "branch_styles": list(cfg.branch_styles),
            "parameters": int(sum(p.numel() for p in model.parameters())),
        },
        "training": training,
        "licence": "CC BY-NC 4.0 (inherited from the training data): non-commercial use only",
        "attribution": ATTRIBUTION,
        "metrics": {},
    }


def write_model(model: StyleERD, path: Path, training: dict, probe: np.ndarray | None = None) -> dict:
    """ONNX graph at ``path`` and its card beside it; returns the card. With a ``probe`` clip
    ``(T, F)``, the card records the ONNX vs torch difference on it (:func:`parity`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    export_onnx(model, path)
    if probe is not None:
        training = {**training, "onnx_torch_max_abs_diff": parity(model, path, probe),
                    "parity_probe_frames": len(probe)}
    info = card(model, training)
    info["name"] = path.stem
    path.with_suffix(".json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def export_random_model(path: Path, styles: list[str], seed: int = 0, neutral: str = "normal") -> None:
    """An untrained tiny generator with the real interface (identity normalisation), for runtime
    tests that must not depend on the shipped model."""
    cfg: ErdConfig = tiny(tuple(styles), neutral)
    torch.manual_seed(seed)
    model = StyleERD(cfg, np.zeros(cfg.n_features), np.ones(cfg.n_features),
                     np.zeros(cfg.n_out), np.ones(cfg.n_out))
    with torch.no_grad():  # make the learned initial state non-trivial, as a trained one is
        for p in model.initial:
            p.normal_(0.0, 0.3)
    write_model(model, Path(path), {"data": "none: random weights", "seed": seed})


def load_generator(checkpoint: Path) -> StyleERD:
    """The weight-averaged generator of a training checkpoint (what the ONNX export holds)."""
    saved = torch.load(checkpoint, weights_only=False)
    cfg = Config(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved["config"].items()})
    erd = cfg.erd(tuple(saved["styles"]))
    model = StyleERD(erd, np.zeros(erd.n_features), np.ones(erd.n_features),
                     np.zeros(erd.n_out), np.ones(erd.n_out))
    model.load_state_dict(saved["ema"])
    return model.eval()
