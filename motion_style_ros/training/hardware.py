"""Where training runs: the device (``--device cpu|cuda|mps``, default the best there is) and, under
``torchrun``, the process group of data-parallel training (NCCL between GPUs, gloo on CPUs).

Mixed precision: the stylizers train in float32 on every device (their critics' gradient
penalties differentiate through a gradient, where float16 underflows and bfloat16 loses the
penalty's small terms, and their LSTMs carry state over many frames); the first panel's judges,
plain convolutional classifiers, run their forward passes in bfloat16 on CUDA (:func:`autocast`),
which needs no loss scaling; the second panel's GRU stays in float32 (cuDNN's bfloat16 RNNs depend
on the GPU). None of it is measured here: this machine has no GPU."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator

import torch
import torch.distributed as dist
from torch import nn
from torch.nn.parallel import DistributedDataParallel

from motion_style_ros.errors import MotionStyleError

DEVICES = ("cpu", "cuda", "mps")


def available() -> list[str]:
    """The devices this machine's torch can train on, best first."""
    found = ["cuda"] if torch.cuda.is_available() else []
    found += ["mps"] if torch.backends.mps.is_available() else []
    return [*found, "cpu"]


def device(name: str | None = None) -> torch.device:
    """The device called ``name`` (None: the best available); under ``torchrun`` on CUDA, this
    process's GPU (``LOCAL_RANK``). A device that is not there is a one-line error naming those that are."""
    here = available()
    name = name or here[0]
    if name not in DEVICES:
        raise MotionStyleError(f"--device {name}: not a device; allowed: {', '.join(DEVICES)}")
    if name not in here:
        why = " (this torch is built without CUDA)" if name == "cuda" and torch.version.cuda is None else ""
        raise MotionStyleError(f"--device {name}: not available on this machine{why}; available: "
                               f"{', '.join(here)}")
    if name == "cuda":
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    return torch.device(name)


def processes() -> int:
    """How many processes ``torchrun`` started (1 without it)."""
    return int(os.environ.get("WORLD_SIZE", "1"))


def _join(where: torch.device) -> bool:
    """Join the process group when started by ``torchrun`` with more than one process (and not
    in it yet); whether it joined."""
    if processes() == 1 or dist.is_initialized():
        return False
    if where.type == "mps":
        raise MotionStyleError("--device mps trains in one process: torchrun needs CUDA (NCCL) or the CPU (gloo)")
    if where.type == "cuda":
        torch.cuda.set_device(where)
    dist.init_process_group("nccl" if where.type == "cuda" else "gloo")
    if rank():  # the skipped-file warnings and the like: once, from rank 0
        logging.getLogger("motion_style_ros").setLevel(logging.ERROR)
    return True


@contextlib.contextmanager
def session(threads: int, name: str | None = None) -> Iterator[torch.device]:
    """A training run's device (:func:`device`), CPU threads and, under ``torchrun``, process group
    (left at the end by the session that joined it: sessions nest)."""
    torch.set_num_threads(threads)
    where = device(name)
    joined = _join(where)
    try:
        yield where
        if joined:
            # every process leaves together: one that tore the group down while rank 0 still
            # exported once aborted in gloo (SIGABRT in CI); not after an error, where the others
            # may never come
            dist.barrier()
    finally:
        if joined:
            dist.destroy_process_group()


def rank() -> int:
    return dist.get_rank() if dist.is_initialized() else 0


def world() -> int:
    return dist.get_world_size() if dist.is_initialized() else 1


def shard(where: torch.device, *tensors: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """This process's share of a global batch (every process draws the same one), on its device."""
    return tuple(t.chunk(world())[rank()].to(where) for t in tensors)


def synced(module: nn.Module, where: torch.device, unused: bool = False) -> nn.Module:
    """``module`` whose gradients ``DistributedDataParallel`` averages over the processes (itself
    in one process); ``unused``: some of its parameters may get no gradient in a step."""
    if world() == 1:
        return module
    return DistributedDataParallel(module, device_ids=[where] if where.type == "cuda" else None,
                                   find_unused_parameters=unused)


def mean_over_processes(value: torch.Tensor, where: torch.device) -> torch.Tensor:
    """The mean of ``value`` over the processes (itself in one): a logged loss, or the normaliser
    of a loss that is a ratio of sums over the batch."""
    if world() == 1:
        return value
    total = value.detach().to(where, copy=True)  # NCCL reduces GPU tensors only
    dist.all_reduce(total)
    return (total / world()).to(value.device)


@contextlib.contextmanager
def rank_zero_first() -> Iterator[None]:
    """Rank 0 runs the block before the others (it writes the caches and the split they then read)."""
    if rank() != 0:
        dist.barrier()
    yield
    if rank() == 0 and dist.is_initialized():
        dist.barrier()


def autocast(where: torch.device, safe: bool = True) -> contextlib.AbstractContextManager:
    """bfloat16 forward passes on CUDA where ``safe`` for the network, float32 otherwise (see the
    module docstring)."""
    return torch.autocast("cuda", dtype=torch.bfloat16, enabled=safe and where.type == "cuda")
