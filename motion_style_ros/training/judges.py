"""Training of the style and content judges on real Bandai takes (both sets) or a user's labelled
BVH folder (:mod:`motion_style_ros.io.user_data`), ONNX export, card.

The judges are instruments: they are trained on real recordings only, scored on the held-out test
takes, and then shipped frozen in ``models/``. No stylizer may use them as a training loss. There
are two panels (see :mod:`motion_style_ros.models.judge`): the first (``judge_<kind>``) picks its
best epoch on the val takes and is what stylizer runs may be compared and selected with; the
second (``judge2_<kind>``) is another architecture on fewer features and another seed, keeps its
last epoch, and only ever reports. A third panel (``judge3_style``, :func:`third_panel`) may guide
choices beside the first.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm

from motion_style_ros.core.features import encode, feature_layout
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation.judges import judge_file
from motion_style_ros.io.datasets import ClipInfo, index_bandai, load_bandai
from motion_style_ros.io.user_data import load_folder
from motion_style_ros.models.judge import ARCHITECTURES, Judge
from motion_style_ros.runtime.contract import JUDGE
from motion_style_ros.training import hardware
from motion_style_ros.training.data import FPS, USER_LICENCE, data_tag, normalisation
from motion_style_ros.training.export import data_fields, export_graph, licence_fields, run_onnx, write_card
from motion_style_ros.training.loop import CHECKPOINTS

WINDOW, HOP = 60, 30  # window-level accuracy: 2 s windows every second


@dataclass(frozen=True)
class Config:
    """Everything that shapes the result; a checkpoint resumes only under the same config."""

    kind: str
    panel: int = 1  # 1: selects its epoch on val, may guide training choices; 2: reports only
    architecture: str = "cnn"  # a key of models.judge.ARCHITECTURES
    # Feature blocks the judge sees. Joint positions and velocities, not local rotations: they
    # mean the same on every rig, so the judges also read motions retargeted from other skeletons.
    inputs: tuple[str, ...] = ("root", "pos", "vel", "contact")
    select: bool = True  # keep the best val epoch (else the last)
    seed: int = 0
    epochs: int = 15
    crops_per_epoch: int = 4096
    batch: int = 64
    crop_frames: tuple[int, int] = (60, 120)
    lr: float = 1e-3
    weight_decay: float = 1e-4
    label_smoothing: float = 0.1
    width: int = 64
    embedding: int = 64
    dropout: float = 0.2
    std_floor: float = 0.05
    data: str = ""  # a user's labelled BVH folder instead of the Bandai sets


def second_panel(kind: str, **changes) -> Config:
    """The second panel's judge of ``kind``, on root motion, joint positions and velocities (no
    contacts), other crop lengths, seed 1, and no look at the val takes at all (last epoch). The
    style judge is a bidirectional GRU; the content judge a wider CNN (a GRU read 0.77 of the
    test takes after 8 epochs, taking waves for raised hands). Not on local rotations: a GRU on
    rotations read 3 of 22 retargeted CMU and Xia walks and runs right (the first panel 19)."""
    gru = kind == "style"
    preset = dict(panel=2, architecture="gru" if gru else "cnn", width=64 if gru else 96,
                  inputs=("root", "pos", "vel"), select=False, seed=1, epochs=8, crop_frames=(45, 150))
    return Config(kind=kind, **{**preset, **changes})


def third_panel(kind: str, **changes) -> Config:
    """The third panel's judge of ``kind``: a CNN on root motion and joint velocities only, seed 2,
    best val epoch. It sees how a body moves but not how it stands (no joint positions, no
    contacts), so a pseudo-pair it agrees on carries the style in the motion, not in a Bandai
    performer's posture. It guides training choices beside panel 1 and never reports."""
    preset = dict(panel=3, inputs=("root", "vel"), seed=2, width=96, crop_frames=(60, 150))
    return Config(kind=kind, **{**preset, **changes})


PANELS = {1: Config, 2: second_panel, 3: third_panel}
# what a judge's card says it is for: the evaluation panels, and panel 3, which only chooses
USES = {
    1: "Evaluation only: style/content recognition accuracy, FMD and content consistency of "
       "stylizer outputs. Never use it as a training loss of a stylizer it judges.",
    3: "Choosing pseudo-pair targets beside judge panel 1 ('motion-style train pairs --agree'); it "
       "reports nothing. Never use it as a training loss of a stylizer.",
}


@dataclass
class Split:
    features: list[np.ndarray]  # (T, F) per clip
    labels: np.ndarray  # (clips,) label indices


def encode_clips(progress: bool = True, folder: str = "") -> list[tuple[ClipInfo, np.ndarray]]:
    """Every Bandai clip of both sets (or every take of a user's ``folder``) with its ``encode()``
    features (every judge trains on them)."""
    if folder:
        user = load_folder(folder, progress)
        clips = list(zip(user.infos, user.motions))
    else:
        clips = load_bandai(index_bandai(), progress=progress)
    return [(info, encode(m)) for info, m in tqdm(clips, desc="features", disable=not progress)]


def make_splits(kind: str, clips: list[tuple[ClipInfo, np.ndarray]]) -> tuple[list[str], dict[str, Split]]:
    """Labels (sorted) and the train/val/test splits for one judge."""
    labels = sorted({getattr(info, kind) for info, _ in clips})
    splits = {}
    for name in ("train", "val", "test"):
        chosen = [(info, f) for info, f in clips if info.split == name]
        splits[name] = Split(
            [f for _, f in chosen], np.array([labels.index(getattr(info, kind)) for info, _ in chosen])
        )
    return labels, splits


def _crop(features: np.ndarray, start: int, length: int) -> np.ndarray:
    """``length`` frames from ``start``; a shorter clip is padded by repeating its edge frames."""
    crop = features[start : start + length]
    missing = length - len(crop)
    return np.pad(crop, ((missing // 2, missing - missing // 2), (0, 0)), mode="edge")


def _batches(split: Split, cfg: Config, rng: np.random.Generator):
    """Random crops of class-balanced random train clips, one crop length per batch."""
    counts = np.bincount(split.labels)
    weights = 1.0 / counts[split.labels]
    weights /= weights.sum()
    for _ in range(cfg.crops_per_epoch // cfg.batch):
        length = int(rng.integers(cfg.crop_frames[0], cfg.crop_frames[1] + 1))
        idx = rng.choice(len(split.labels), size=cfg.batch, p=weights)
        starts = rng.integers(0, [max(len(split.features[i]) - length, 0) + 1 for i in idx])
        crops = [_crop(split.features[i], int(s), length) for i, s in zip(idx, starts)]
        yield torch.from_numpy(np.stack(crops)), torch.from_numpy(split.labels[idx])


@torch.no_grad()
def _predict(model: Judge, clips: list[np.ndarray]) -> np.ndarray:
    """Class probabilities ``(N, classes)``, each clip classified whole."""
    model.eval()
    where = next(model.parameters()).device
    return np.concatenate(
        [torch.softmax(model(torch.from_numpy(f)[None].to(where))[0].float(), -1).cpu().numpy() for f in clips]
    )


def _windows(split: Split) -> tuple[list[np.ndarray], np.ndarray]:
    """WINDOW-frame windows every HOP frames of each clip (a shorter clip is one window)."""
    out, labels = [], []
    for f, label in zip(split.features, split.labels):
        starts = range(0, max(len(f) - WINDOW, 0) + 1, HOP)
        out += [f[s : s + WINDOW] for s in starts]
        labels += [label] * len(starts)
    return out, np.array(labels)


def _scores(model: Judge, split: Split) -> tuple[float, float]:
    """Clip-level accuracy and mean cross-entropy."""
    probs = _predict(model, split.features)
    loss = -np.log(probs[np.arange(len(probs)), split.labels] + 1e-12).mean()
    return float((probs.argmax(-1) == split.labels).mean()), float(loss)


def input_columns(inputs: tuple[str, ...] | list[str]) -> np.ndarray:
    """Feature columns of the named ``feature_layout()`` blocks."""
    slices = feature_layout().slices
    unknown = sorted(set(inputs) - set(slices))
    if unknown:
        raise ValueError(f"unknown feature blocks {unknown}; allowed: {', '.join(slices)}")
    return np.concatenate([np.arange(slices[b].start, slices[b].stop) for b in inputs])


def export_onnx(model: Judge, path: Path) -> None:
    """ONNX graph on raw features with dynamic batch and time axes; outputs logits, embedding."""
    # Edge padding exports as Slice ops it cannot fold; harmless, and not the user's concern. The
    # GRU has no initial-state input, so ONNX Runtime starts it at zeros for any batch size.
    export_graph(model, (torch.zeros(1, 64, len(model.mean)),), path, JUDGE, timed=("features",),
                 time_axis="time", quiet=("Constant folding", "Exporting a model to ONNX with a batch_size"))


@torch.no_grad()
def parity(model: nn.Module, path: Path, clips: list[np.ndarray]) -> tuple[float, int]:
    """Largest logit difference between the ONNX graph and the torch network on ``clips`` (each
    whole, batch 1, as the evaluation runs them), and how many clips."""
    worst = 0.0
    model.eval()
    for f in clips:
        expected = model(torch.from_numpy(f[None]))[0].numpy()
        worst = max(worst, float(np.abs(run_onnx(path, JUDGE, f[None])[0] - expected).max()))
    return worst, len(clips)


def train(
    cfg: Config,
    out_dir: Path,
    clips: list[tuple[ClipInfo, np.ndarray]] | None = None,
    checkpoints: Path = CHECKPOINTS,
    threads: int = 2,
    progress: bool = True,
    device: str | None = None,
    licence: str | None = None,
) -> dict | None:
    """Train one judge (resuming from its checkpoint, on any device) on ``device`` (default: the
    best there is; under ``torchrun``, data-parallel: every process draws the same batches and
    trains on its share), export it to ``out_dir``; returns its card (None in the processes other
    than rank 0, which export nothing).

    ``clips`` are :func:`encode_clips`' output, loaded here when not given.
    """
    started = time.perf_counter()
    with hardware.session(threads, device) as where:
        rank = hardware.rank()
        with hardware.rank_zero_first():
            clips = clips if clips is not None else encode_clips(progress and not rank, cfg.data)
        labels, splits = make_splits(cfg.kind, clips)
        model, state, earlier = _fit(cfg, labels, splits, checkpoints, where, progress and not rank)
    if rank:
        return None
    model.load_state_dict(state["best"]["model"])
    model.cpu()
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = out_dir / judge_file(cfg.kind, cfg.panel)
    export_onnx(model, onnx_path)
    card = _card(cfg, model, labels, splits, state, onnx_path, licence)
    card["onnx_torch_max_abs_diff"], card["parity_probe_clips"] = parity(model, onnx_path, splits["test"].features[:4])
    card["training"]["wall_time_s"] = round(earlier + time.perf_counter() - started, 1)
    write_card(onnx_path, card)
    return card


def _fit(cfg: Config, labels: list[str], splits: dict[str, Split], checkpoints: Path, where: torch.device,
         progress: bool) -> tuple[Judge, dict, float]:
    """The judge trained for ``cfg.epochs`` (resuming from its checkpoint; only rank 0 prints and
    writes it), its state (history, best epoch) and the seconds of the runs it resumed."""
    rank = hardware.rank()
    if cfg.batch % hardware.world():
        raise MotionStyleError(f"batch {cfg.batch} does not split over {hardware.world()} processes")
    train_split = splits["train"]
    mean, std = normalisation(train_split.features, cfg.std_floor)
    torch.manual_seed(cfg.seed)  # initial weights
    model = ARCHITECTURES[cfg.architecture](mean, std, len(labels), cfg.width, cfg.embedding,
                                            cfg.dropout, input_columns(cfg.inputs)).to(where)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)

    checkpoints.mkdir(parents=True, exist_ok=True)
    ckpt_path = checkpoints / f"{Path(judge_file(cfg.kind, cfg.panel)).stem}{data_tag(cfg.data)}_seed{cfg.seed}.pt"
    state = {"epoch": -1, "best": None, "history": [], "train_seconds": 0.0}
    earlier = 0.0
    if ckpt_path.exists():
        saved = torch.load(ckpt_path, map_location="cpu", weights_only=False)
        if {"data": "", **saved["config"]} == {**asdict(cfg), "epochs": None}:
            model.load_state_dict(saved["model"])
            optimizer.load_state_dict(saved["optimizer"])
            state = saved["state"]
            earlier = state["train_seconds"]  # spent by the runs this one resumes
            if not rank:
                print(f"resuming {ckpt_path} after epoch {state['epoch'] + 1}")
        elif not rank:
            print(f"{ckpt_path} was made with other settings; starting afresh")
    net = hardware.synced(model, where)

    for epoch in range(state["epoch"] + 1, cfg.epochs):
        t0 = time.perf_counter()
        # Seeded per epoch, so a resumed run follows the same path as an uninterrupted one.
        rng = np.random.default_rng([cfg.seed, epoch])
        torch.manual_seed(cfg.seed * 100_003 + epoch)
        model.train()
        losses = []
        bar = tqdm(
            _batches(train_split, cfg, rng),
            total=cfg.crops_per_epoch // cfg.batch,
            desc=f"{cfg.kind} epoch {epoch + 1}/{cfg.epochs}",
            disable=not progress,
        )
        for x, y in bar:
            x, y = hardware.shard(where, x, y)
            with hardware.autocast(where, safe=cfg.architecture == "cnn"):
                logits, _ = net(x)
            loss = F.cross_entropy(logits.float(), y, label_smoothing=cfg.label_smoothing)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
            bar.set_postfix(loss=f"{np.mean(losses[-20:]):.3f}")
        # The second panel never looks at the val takes: it keeps its last epoch.
        val_acc, val_loss = _scores(model, splits["val"]) if cfg.select else (None, None)
        train_loss = float(hardware.mean_over_processes(torch.tensor(np.mean(losses)), where))
        state["history"].append({
            "epoch": epoch + 1, "train_loss": train_loss,
            "val_accuracy": val_acc, "val_loss": val_loss,
        })
        best = state["best"]
        if not cfg.select or best is None or (val_acc, -val_loss) > (best["val_accuracy"], -best["val_loss"]):
            state["best"] = {
                "epoch": epoch + 1,
                "val_accuracy": val_acc,
                "val_loss": val_loss,
                "model": {k: v.clone() for k, v in model.state_dict().items()},
            }
        state["epoch"] = epoch
        state["train_seconds"] += time.perf_counter() - t0
        if rank:
            continue
        print(f"{cfg.kind} epoch {epoch + 1}: loss {train_loss:.3f}"
              + (f", val accuracy {val_acc:.3f}" if cfg.select else ""))
        tmp = ckpt_path.with_suffix(".tmp")
        torch.save(
            {"config": {**asdict(cfg), "epochs": None}, "model": model.state_dict(),
             "optimizer": optimizer.state_dict(), "state": state},
            tmp,
        )
        tmp.replace(ckpt_path)
    return model, state, earlier


def _card(
    cfg: Config, model: Judge, labels: list[str], splits: dict[str, Split], state: dict, onnx_path: Path,
    licence: str | None = None,
) -> dict:
    test = splits["test"]
    probs = _predict(model, test.features)
    pred = probs.argmax(-1)
    confusion = np.zeros((len(labels), len(labels)), dtype=int)
    np.add.at(confusion, (test.labels, pred), 1)
    windows, window_labels = _windows(test)
    window_pred = _predict(model, windows).argmax(-1)
    layout = feature_layout()
    best = state["best"]
    crop_s = [round(n / FPS, 1) for n in cfg.crop_frames]
    data = (f"the user's labelled BVH folder {cfg.data}, 'train' takes" if cfg.data
            else "Bandai Namco Research Motion Datasets 1 and 2, 'train' takes")
    training = {
        "data": data + "; " + (f"selection on {'' if cfg.data else 'dataset-2 '}'val' takes" if cfg.select
                               else "the last epoch kept "
                               "(val takes never looked at)")
                + "; test on held-out 'test' takes (split by take, never by window)",
        **({"licence": licence or USER_LICENCE} if cfg.data else {}),
    }
    return {
        "name": onnx_path.stem,
        "task": f"classify the {cfg.kind} of a motion clip ("
                + ("a judge that chooses distillation targets)" if cfg.panel == 3 else "an independent evaluation judge)"),
        "use": USES.get(cfg.panel, USES[1]),
        "labels": labels,
        "inputs": {
            "features": f"(batch, time, {layout.size}) float32: motion_style_ros.core.features.encode() "
                        "of a canonical-skeleton motion at 30 fps, raw (normalised inside the graph)"
        },
        "outputs": {
            "logits": f"(batch, {len(labels)}) unnormalised class scores, in the order of 'labels'",
            "embedding": f"(batch, {cfg.embedding}) time-averaged features before the classifier "
                         "(the space of FMD and content consistency)",
        },
        **data_fields("canonical (22 joints, Bandai Namco / Unity humanoid names, metres)"),
        "min_frames": 1,
        "clip_length_note": "Convolutions pad by repeating edge frames, so any length works; "
                            f"trained on {crop_s[0]:g}-{crop_s[1]:g} s crops, clips under 1 s carry "
                            "little style.",
        "panel": cfg.panel,
        "architecture": (
            f"Conv1d x4 (kernel 5, LeakyReLU 0.2, width {cfg.width}; strides 1,2,1,2; dilation 2 in "
            f"the third; replicate padding; receptive field 33 frames) -> mean over time -> "
            f"{cfg.embedding}-d embedding -> dropout -> linear"
            if cfg.architecture == "cnn" else
            f"dropout -> linear {cfg.width} + tanh -> 2-layer bidirectional GRU (width {cfg.width}) "
            f"-> mean and max over time -> linear {cfg.embedding} + tanh (embedding) -> dropout -> linear"
        ),
        "embedding_size": cfg.embedding,
        "parameters": int(sum(p.numel() for p in model.parameters())),
        "normalisation": "per-feature mean and std of all train frames (std floored at "
                         f"{cfg.std_floor}), stored in the graph as constants",
        "training": {
            **training,
            "labels": "styles from motion_style_ros.io.datasets.style_label (dataset-1 styles "
                      "named like a dataset-2 style carry the suffix -d1)",
            "clips": {name: len(s.labels) for name, s in splits.items()},
            "command": f"motion-style train judges --panel {cfg.panel} --kind {cfg.kind}"
                       + (f" --data {cfg.data}" if cfg.data else ""),
            "config": asdict(cfg),
            "optimizer": "Adam, cross-entropy with label smoothing, class-balanced sampling of "
                         "random crops",
            "selected_epoch": best["epoch"],
            "history": state["history"],
        },
        "accuracy": {
            "val_clip": None if best["val_accuracy"] is None else round(best["val_accuracy"], 4),
            "test_clip": round(float((pred == test.labels).mean()), 4),
            "test_window": round(float((window_pred == window_labels).mean()), 4),
            "test_window_frames": WINDOW,
            "test_window_hop": HOP,
            "test_clips": len(test.labels),
            "test_windows": len(window_labels),
        },
        "confusion_matrix": {
            "split": "test, clip level",
            "rows": "true label",
            "columns": "predicted label",
            "labels": labels,
            "matrix": confusion.tolist(),
        },
        **licence_fields(training),
    }
