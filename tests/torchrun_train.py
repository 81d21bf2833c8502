"""``a2cf-mb`` for ``tests/test_distributed.py``: the CLI, with each rank's final parameters saved.

Run by ``python -m torch.distributed.run --nproc_per_node K tests/torchrun_train.py train ...``.
Every rank writes ``$A2CF_TEST_PARAMS_DIR/rank<RANK>.pt``: the actor's and critic's state dicts
when ``learn`` returns, which the test compares across ranks (only rank 0 writes checkpoints).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import torch

from a2cf_mb.cli import main
from rl.training.runner import A2CFRunner

_learn = A2CFRunner.learn


def _learn_and_save_params(self: A2CFRunner, *args, **kwargs) -> None:
    _learn(self, *args, **kwargs)
    policy = self.alg.get_policy()
    state = {
        "actor": {k: v.detach().clone() for k, v in policy.state_dict().items()},
        "critic": {k: v.detach().clone() for k, v in self.alg.critic.state_dict().items()},
    }
    torch.save(state, Path(os.environ["A2CF_TEST_PARAMS_DIR"]) / f"rank{self.gpu_global_rank}.pt")


A2CFRunner.learn = _learn_and_save_params

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
