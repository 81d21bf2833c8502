"""Multi-process training with ``torchrun`` on the CPU (gloo): one run folder, one set of
checkpoints, the same policy on every rank; and the per-rank devices and seeds."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from rl.a2cf.config import CurriculumConfig
from rl.envs.config import EnvConfig
from rl.runs.folder import CHECKPOINT_DIR, LAST_CHECKPOINT
from rl.training.config import TrainConfig
from rl.training.distributed import ProcessRank, check_learner_device, rank_device, rank_env_config
from rl.training.runner import check_distributed

ROOT = Path(__file__).resolve().parents[1]
ALONE = ProcessRank(rank=0, local_rank=0, world_size=1)
RANK_1_OF_2 = ProcessRank(rank=1, local_rank=1, world_size=2)
ENCODER_KEYS = "encoder."
"""The actor's history encoder (VAE), trained by ``A2CFPPO.update_encoder`` after PPO's update."""


def test_devices_and_seeds_are_per_rank_under_torchrun_only() -> None:
    assert rank_device("cuda", RANK_1_OF_2) == "cuda:1"
    assert rank_device("cpu", RANK_1_OF_2) == "cpu"
    assert rank_device("cuda", ALONE) == "cuda"
    env = EnvConfig(seed=7, backend="warp", device="cuda")
    assert rank_env_config(env, ALONE) is env  # a single process is unchanged
    assert rank_env_config(env, RANK_1_OF_2) == dataclasses.replace(env, seed=8, device="cuda:1")
    check_learner_device("cuda:1", RANK_1_OF_2)
    check_learner_device("cpu", RANK_1_OF_2)
    with pytest.raises(ValueError, match="pass --device cuda"):
        check_learner_device("cuda:0", RANK_1_OF_2)


def test_a_torchrun_job_needs_a_run_name_and_no_rank_0_evaluation() -> None:
    check_distributed(TrainConfig(), ALONE)
    with pytest.raises(ValueError, match="--run-name"):
        check_distributed(TrainConfig(), RANK_1_OF_2)
    check_distributed(TrainConfig(run_name="job"), RANK_1_OF_2)
    cfg = TrainConfig(run_name="job", curriculum=CurriculumConfig(skill_measure="evaluation"))
    with pytest.raises(ValueError, match="skill_measure 'evaluation'"):
        check_distributed(cfg, RANK_1_OF_2)


TRAIN_FLAGS = [
    "train", "--task", "stand", "--mode", "a2cf", "--env-num-envs", "4",
    "--env-num-threads", "1", "--iterations", "2", "--num-steps-per-env", "8",
    "--run-name", "job", "--save-interval", "1", "--eval-interval", "0",
    "--ppo-num-mini-batches", "2", "--ppo-num-learning-epochs", "1",
    "--model-motion-hidden-dims", "32", "32", "--model-critic-hidden-dims", "32",
    "--model-encoder-hidden-dims", "32", "--model-assist-hidden-dims", "16",
]  # fmt: skip


@pytest.fixture(scope="module")
def torchrun_job(tmp_path_factory) -> tuple[Path, dict[int, dict]]:
    """``torchrun --nproc_per_node 2`` of 2 stand iterations on the CPU: (runs folder, final
    parameters of each rank)."""
    out = tmp_path_factory.mktemp("runs")
    params = tmp_path_factory.mktemp("params")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "A2CF_TEST_PARAMS_DIR": str(params)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    command = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
        str(ROOT / "tests" / "torchrun_train.py"), *TRAIN_FLAGS, "--out", str(out),
    ]  # fmt: skip
    done = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    ranks = {r: torch.load(params / f"rank{r}.pt", weights_only=True) for r in (0, 1)}
    return out, ranks


def _differing(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> list[str]:
    assert a.keys() == b.keys()
    return [key for key in a if not torch.equal(a[key], b[key])]


def test_torchrun_on_the_cpu_trains_one_run_with_one_policy(torchrun_job) -> None:
    out, ranks = torchrun_job
    assert [p.name for p in out.iterdir()] == ["job"]  # one run folder, written by rank 0
    run = out / "job"
    checkpoints = sorted(p.name for p in (run / CHECKPOINT_DIR).iterdir())
    assert checkpoints == [LAST_CHECKPOINT, "model_1.pt", "model_2.pt"]
    assert len(list(run.glob("events.out.tfevents*"))) == 1
    assert not (run / "run.lock").exists()
    saved = torch.load(run / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    assert saved["completed_iterations"] == 2
    assert _differing(saved["actor_state_dict"], ranks[0]["actor"]) == []
    assert _differing(saved["critic_state_dict"], ranks[0]["critic"]) == []
    # PPO's parameters and the observation normalisers: broadcast from rank 0 at the start, then
    # the same averaged gradients and statistics on every rank.
    ppo_actor = _differing(ranks[0]["actor"], ranks[1]["actor"])
    assert [k for k in ppo_actor if not k.startswith(ENCODER_KEYS)] == []  # the encoder: below
    assert _differing(ranks[0]["critic"], ranks[1]["critic"]) == []


def test_torchrun_ranks_share_the_history_encoder(torchrun_job) -> None:
    _, ranks = torchrun_job
    assert _differing(ranks[0]["actor"], ranks[1]["actor"]) == []
