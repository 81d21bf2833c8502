"""Multi-process training under ``torchrun``: this process's rank, its devices and seed, and the
CPU process group.

rsl-rl's runner trains with ``torchrun`` when ``WORLD_SIZE`` > 1: it broadcasts the parameters at
the start, averages the gradients of every update, and only rank 0 writes logs and checkpoints.
It wants the learner on ``cuda:LOCAL_RANK`` with NCCL. Here the device ``cuda`` means that device
(:func:`rank_device`), and the device ``cpu`` uses the gloo backend (:func:`init_cpu_process_group`,
used by :class:`rl.training.runner.A2CFRunner`), so the same command runs on CPUs too. Outside torchrun
every function is the identity and nothing changes.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, replace

import torch.distributed as dist

from rl.envs.config import EnvConfig


@dataclass(frozen=True)
class ProcessRank:
    """Where this process stands in a ``torchrun`` job (``rank 0 of 1`` outside one)."""

    rank: int  # global rank, RANK [-]
    local_rank: int  # rank on this node, LOCAL_RANK: the GPU index [-]
    world_size: int  # processes in the job, WORLD_SIZE [-]

    @property
    def distributed(self) -> bool:
        """Whether this is one process of several."""
        return self.world_size > 1

    @property
    def main(self) -> bool:
        """Whether this process writes the run folder (rank 0, as rsl-rl's logger decides)."""
        return self.rank == 0


def process_rank() -> ProcessRank:
    """This process's rank, from the variables ``torchrun`` sets."""
    return ProcessRank(
        rank=int(os.environ.get("RANK", "0")),
        local_rank=int(os.environ.get("LOCAL_RANK", "0")),
        world_size=int(os.environ.get("WORLD_SIZE", "1")),
    )


def rank_device(device: str, rank: ProcessRank | None = None) -> str:
    """The torch (or Warp) device of this process: under torchrun ``cuda`` is ``cuda:LOCAL_RANK``,
    one GPU per process; anything else is kept (rsl-rl refuses a ``cuda:N`` of another rank)."""
    rank = rank or process_rank()
    return f"cuda:{rank.local_rank}" if rank.distributed and device == "cuda" else device


def rank_seed(seed: int, rank: ProcessRank | None = None) -> int:
    """The seed of this process: ``seed + RANK``, so that the ranks collect different episodes."""
    return seed + (rank or process_rank()).rank


def rank_env_config(cfg: EnvConfig, rank: ProcessRank | None = None) -> EnvConfig:
    """The env config of this process: its own seed and device (itself outside torchrun)."""
    rank = rank or process_rank()
    if not rank.distributed:
        return cfg
    return replace(cfg, seed=rank_seed(cfg.seed, rank), device=rank_device(cfg.device, rank))


def check_learner_device(device: str, rank: ProcessRank | None = None) -> None:
    """Refuse a learner device a torchrun job cannot use, naming the one to give."""
    rank = rank or process_rank()
    if not rank.distributed or device in ("cpu", f"cuda:{rank.local_rank}"):
        return
    expected = "cuda" if re.fullmatch(r"cuda(:\d+)?", device) else "cpu or cuda"
    raise ValueError(
        f"under torchrun each process learns on its own device (cpu, or cuda:LOCAL_RANK); "
        f"rank {rank.rank} got --device {device}: pass --device {expected}"
    )


def init_cpu_process_group(rank: ProcessRank) -> None:
    """Join the job's gloo process group (CPU tensors); no CUDA call is made."""
    if not dist.is_initialized():
        dist.init_process_group("gloo", rank=rank.rank, world_size=rank.world_size)


def close_process_group() -> None:
    """Leave the job's process group, if this process is in one."""
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()
