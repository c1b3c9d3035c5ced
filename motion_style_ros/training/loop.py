"""The resumable training loop every stylizer trainer runs: a time and iteration budget counted
over all resumed runs, a loss log (``losses.jsonl``), validation, and checkpoints that a later run
continues exactly (every iteration draws its data from a generator seeded by the seed and the
iteration, so a resumed run repeats what an uninterrupted one would have done).

On any device (checkpoints are loaded onto the CPU first, so a run resumes on another device), and
data-parallel under ``torchrun``: every process draws the same global batch (the config's
``batch``) and trains on its share (:meth:`ResumableTrainer.shard`) through
``DistributedDataParallel`` (:meth:`ResumableTrainer.synced`), so N processes follow one process
with the same config; the logged losses are the mean over processes, and only rank 0 logs, shows
progress and writes checkpoints, which resume in one process."""

from __future__ import annotations

import json
import sys
import time
from abc import ABC, abstractmethod
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
from torch import nn
from tqdm import tqdm

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.training import hardware
from motion_style_ros.training.data import (
    Data,
    DataConfig,
    data_tag,
    load_for,
    normalisation,
    recipe,
    windows,
)
from motion_style_ros.training.losses import Losses

CHECKPOINTS = Path.home() / ".cache" / "motion_style_ros" / "checkpoints"
PROGRESS_INTERVAL = 0.1 if sys.stderr.isatty() else 30.0  # progress lines in a log file: one per 30 s


def update_average(average: nn.Module, live: nn.Module, decay: float) -> None:
    """Move the exponential moving average of ``live``'s weights one step (what is exported)."""
    with torch.no_grad():
        for p_avg, p in zip(average.parameters(), live.parameters()):
            p_avg.lerp_(p, 1 - decay)


class ResumableTrainer(ABC):
    """The loop, checkpoints and log of a trainer in ``checkpoints/<FOLDER>_<seed>/``
    (``checkpoint.pt``, ``losses.jsonl``). A model's trainer builds its networks and optimisers
    after calling this ``__init__``, sets the class attributes below, has a ``model`` (the network
    the loop puts in train mode) and defines :meth:`step` and :meth:`validate`."""

    FOLDER: str  # the checkpoint folder's prefix
    LABEL: str  # the progress bar's
    SHOWN: tuple[str, ...]  # the logged losses the progress bar shows
    PARTS: tuple[str, ...]  # the attributes (modules, optimisers) a checkpoint holds besides the state

    def __init__(self, cfg: DataConfig, data: Data, checkpoints: Path, progress: bool,
                 device: torch.device | None = None) -> None:
        self.rank, self.world = hardware.rank(), hardware.world()
        if cfg.batch % self.world:  # every config here has a batch
            raise MotionStyleError(f"batch {cfg.batch} does not split over {self.world} processes")
        self.cfg, self.data, self.progress = cfg, data, progress and self.rank == 0
        self.device = device or torch.device("cpu")
        self.dir = self.folder(checkpoints, cfg.seed, cfg.data)
        self.state = {"iteration": 0, "train_seconds": 0.0, "val": []}

    def normalised_losses(self) -> tuple[np.ndarray, np.ndarray]:
        """The train split's per-feature mean and std (std floored at the config's ``std_floor``),
        what the networks normalise with, and ``self.losses`` (the shared loss terms) on them, on
        this trainer's device."""
        mean, std = normalisation(self.data.splits["train"].features, self.cfg.std_floor)
        self.losses = Losses(self.cfg, mean, std).to(self.device)
        return mean, std

    def shard(self, *tensors: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """This process's share of a global batch, on its device (:func:`hardware.shard`)."""
        return hardware.shard(self.device, *tensors)

    def mean_over_processes(self, value: torch.Tensor) -> torch.Tensor:
        """:func:`hardware.mean_over_processes` on this trainer's device."""
        return hardware.mean_over_processes(value, self.device)

    def synced(self, module: nn.Module, unused: bool = False) -> nn.Module:
        """:func:`hardware.synced` on this trainer's device."""
        return hardware.synced(module, self.device, unused)

    def pair_windows(self, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``cfg.distil_batch`` windows of the pseudo-pairs (``DataConfig.distil``): inputs
        ``(B, window, F)``, their styles and their targets' ``[root | rot6d]`` frames; all empty
        where the run distils nothing."""
        pairs, width = self.data.pairs, self.data.splits["train"].features[0].shape[1]
        if pairs is None:
            empty = torch.zeros((0, self.cfg.window, width), device=self.device)
            return empty, torch.zeros(0, dtype=torch.long, device=self.device), empty[..., :0]
        w, styles, _ = windows(pairs, self.cfg.window, self.cfg.distil_batch, rng)
        w, styles = self.shard(w, styles)
        return w[..., :width], styles, w[..., width:]

    @abstractmethod
    def step(self, iteration: int) -> dict[str, float]:
        """One update on the data of ``iteration``; returns its loss terms."""

    @abstractmethod
    def validate(self) -> dict[str, float]:
        """Figures on fixed val windows (logged every ``val_every`` iterations and at the end)."""

    @classmethod
    def folder(cls, checkpoints: Path, seed: int, data: str = "") -> Path:
        """Where the run of ``seed`` (on the user's folder ``data``) keeps its checkpoint and log."""
        return checkpoints / f"{cls.FOLDER}{data_tag(data)}_{seed}"

    @property
    def checkpoint(self) -> Path:
        return self.dir / "checkpoint.pt"

    @property
    def log(self) -> Path:
        return self.dir / "losses.jsonl"

    def settings(self) -> dict:
        """What a checkpoint must have been made with to be resumed: the config and the labels."""
        return {"config": asdict(self.cfg), "styles": list(self.data.styles),
                "contents": list(self.data.contents)}

    def _read(self, checkpoint: Path) -> dict:
        """A checkpoint on the CPU; a config from before a field existed reads as its default."""
        saved = torch.load(checkpoint, map_location="cpu", weights_only=False)
        saved["config"] = {**asdict(type(self.cfg)()), **saved["config"]}
        return saved

    def save(self) -> None:
        if self.rank:
            return
        self.dir.mkdir(parents=True, exist_ok=True)
        tmp = self.checkpoint.with_suffix(".tmp")
        torch.save({**self.settings(), **{name: getattr(self, name).state_dict() for name in self.PARTS},
                    "state": self.state}, tmp)
        tmp.replace(self.checkpoint)

    def _load_parts(self, saved: dict) -> None:
        for name in self.PARTS:
            getattr(self, name).load_state_dict(saved[name])

    def resume(self) -> bool:
        """Continue from the checkpoint if there is one; log lines written after it are dropped."""
        if not self.checkpoint.exists():
            return False
        saved = self._read(self.checkpoint)
        if {k: saved[k] for k in ("config", "styles", "contents")} != self.settings():
            raise MotionStyleError(
                f"{self.checkpoint} was made with other settings or data; train without --resume "
                "to start afresh, or use another --seed"
            )
        self._load_parts(saved)
        self.state = saved["state"]
        if self.log.exists() and not self.rank:
            kept = [line for line in self.log.read_text().splitlines()
                    if json.loads(line)["iteration"] <= self.state["iteration"]]
            self.log.write_text("".join(line + "\n" for line in kept))
        return True

    def initialise(self, checkpoint: Path, networks: tuple[str, ...]) -> None:
        """Continue another run (its weights, optimiser states, iteration count and time) under this
        run's other settings; the config fields ``networks`` and the data must be the same."""
        if not checkpoint.exists():
            raise MotionStyleError(f"{checkpoint}: no checkpoint to start from")
        saved = self._read(checkpoint)
        mine = self.settings()
        if ([saved["config"].get(k) for k in networks] != [mine["config"][k] for k in networks]
                or (saved["styles"], saved["contents"]) != (mine["styles"], mine["contents"])):
            raise MotionStyleError(f"{checkpoint} has other networks or data than this run "
                                   f"({', '.join(networks)}, styles and contents must match)")
        self._load_parts(saved)
        self.state = {**saved["state"], "init_from": {
            "checkpoint": str(checkpoint), "iteration": saved["state"]["iteration"],
            "train_seconds": round(saved["state"]["train_seconds"], 1), "config": saved["config"]}}

    @classmethod
    def started(cls, cfg: DataConfig, data: Data, checkpoints: Path, progress: bool, resume: bool,
                device: torch.device | None = None) -> ResumableTrainer:
        """A trainer continuing from its checkpoint (``resume`` and there is one) or afresh."""
        trainer = cls(cfg, data, checkpoints, progress, device)
        if resume and trainer.resume():
            if not trainer.rank:
                print(f"resuming {trainer.checkpoint} at iteration {trainer.state['iteration']}")
        elif not resume and not trainer.rank:
            trainer.fresh_start()
        return trainer

    def fresh_start(self) -> None:
        """Forget an earlier run's checkpoint and log (other files in the folder stay: a trainer
        keys them by their own settings)."""
        for path in (self.checkpoint, self.log):
            path.unlink(missing_ok=True)

    def _append_log(self, entry: dict) -> None:
        if self.rank:
            return
        self.dir.mkdir(parents=True, exist_ok=True)
        with open(self.log, "a") as f:
            f.write(json.dumps(entry) + "\n")

    def _log_losses(self, recent: list[dict[str, float]], seconds: float) -> dict[str, float]:
        """Log the mean of each loss term over the ``recent`` steps; returns the means."""
        # the mean over processes: the loss of the global batch
        means = self.mean_over_processes(torch.tensor([np.mean([r[k] for r in recent]) for k in recent[0]],
                                                      dtype=torch.float64))
        means = {k: round(float(v), 5) for k, v in zip(recent[0], means)}
        self._append_log({"iteration": self.state["iteration"], "seconds": round(seconds, 1), **means})
        return means

    def _log_validation(self, seconds: float) -> None:
        self.state["val"].append({"iteration": self.state["iteration"], **self.validate()})
        self._append_log({**self.state["val"][-1], "seconds": round(seconds, 1)})

    def run(self, minutes: float | None = None, iterations: int | None = None, log_every: int = 25,
            val_every: int = 500, checkpoint_minutes: float = 5.0) -> None:
        """Train until ``minutes`` of training (over all resumed runs) or ``iterations`` in total."""
        budget_s = float("inf") if minutes is None else 60.0 * minutes
        last_iteration = iterations if iterations is not None else 2**62
        state = self.state
        started = time.perf_counter()

        def spent() -> float:
            return state["train_seconds"] + time.perf_counter() - started

        def out_of_time() -> bool:  # rank 0's clock decides for every process
            if self.world == 1:
                return spent() >= budget_s
            late = torch.tensor(float(spent() >= budget_s), device=self.device)
            dist.broadcast(late, 0)
            return bool(late)

        last_save, recent = time.perf_counter(), []
        bar = tqdm(total=iterations, initial=state["iteration"], desc=self.LABEL, unit="it",
                   disable=not self.progress, mininterval=PROGRESS_INTERVAL)
        while state["iteration"] < last_iteration and not out_of_time():
            self.model.train()
            recent.append(self.step(state["iteration"]))
            state["iteration"] += 1
            bar.update()
            if state["iteration"] % log_every == 0 or state["iteration"] == last_iteration:
                means = self._log_losses(recent, spent())
                bar.set_postfix(**{k: means[k] for k in self.SHOWN},
                                left=f"{max(budget_s - spent(), 0) / 60:.0f}min" if minutes else None,
                                refresh=False)
                recent = []
            if state["iteration"] % val_every == 0:
                self._log_validation(spent())
            if time.perf_counter() - last_save > 60 * checkpoint_minutes:
                state["train_seconds"] = spent()
                started, last_save = time.perf_counter(), time.perf_counter()
                self.save()
        bar.close()
        if recent:
            self._log_losses(recent, spent())
        if not state["val"] or state["val"][-1]["iteration"] != state["iteration"]:
            self._log_validation(spent())
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
                "val": self.state["val"]}


def run_record(trainer: ResumableTrainer, setup_seconds: float, command: str) -> dict:
    """The card's account of a finished run: the command that continues it, seed, config, wall
    time (setup and training over all resumed runs) and the loss history."""
    return {"command": command, "seed": trainer.cfg.seed, "config": asdict(trainer.cfg),
            "wall_time_s": round(trainer.state["train_seconds"] + setup_seconds, 1),
            "history": trainer.summary()}


def fit(trainer_class: type[ResumableTrainer], cfg: DataConfig, data: Data | None, checkpoints: Path,
        threads: int, device: str | None, progress: bool, resume: bool, minutes: float | None,
        iterations: int | None, log_every: int, val_every: int,
        prepare=None) -> tuple[ResumableTrainer, Data, float]:
    """A model's run, as every trainer's ``train`` makes it: on ``device`` (under ``torchrun``, in
    every process), the data loaded (rank 0 first), the trainer started or resumed, ``prepare``
    (e.g. continuing another run) applied, then trained; the trainer, the data and the setup time
    (s)."""
    with hardware.session(threads, device) as where:
        started = time.perf_counter()
        with hardware.rank_zero_first():
            data = data or load_for(cfg, progress and not hardware.rank())
        trainer = trainer_class.started(cfg, data, checkpoints, progress, resume, where)
        if prepare is not None:
            prepare(trainer)
        setup_s = time.perf_counter() - started
        trainer.run(minutes, iterations, log_every=log_every, val_every=val_every)
    return trainer, data, setup_s


def fit_for_export(trainer_class: type[ResumableTrainer], cfg: DataConfig, data: Data | None,
                   checkpoints: Path, threads: int, device: str | None, progress: bool, resume: bool,
                   minutes: float | None, iterations: int | None, log_every: int, val_every: int,
                   command: str, licence: str | None, prepare=None
                   ) -> tuple[ResumableTrainer, Data, dict, np.ndarray] | None:
    """:func:`fit`, then what every trainer's export takes on rank 0: the trainer, the data, the
    card's record of the run (:func:`card_record`) and the probe clip (the longest val clip, on
    which the export compares ONNX with torch); None in the other processes (they export nothing)."""
    trainer, data, setup_s = fit(trainer_class, cfg, data, checkpoints, threads, device, progress, resume,
                                 minutes, iterations, log_every, val_every, prepare)
    if trainer.rank:
        return None
    probe = max(data.splits["val"].features, key=len)
    return trainer, data, card_record(trainer, data, setup_s, command, licence), probe


def card_record(trainer: ResumableTrainer, data: Data, setup_seconds: float, command: str,
                licence: str | None) -> dict:
    """What every model's card says of its run: the data recipe, clips per split and the run."""
    clips = {k: len(c.features) for k, c in data.splits.items()}
    if data.unlabelled_names:  # eval --unseen leaves these out
        clips["unlabelled"] = list(data.unlabelled_names)
    if data.pairs_record is not None:
        clips["pairs"] = data.pairs_record
    return {**recipe(trainer.cfg, licence), "clips": clips, **run_record(trainer, setup_seconds, command)}
