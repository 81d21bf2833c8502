"""Training needs MuJoCo, torch and rsl-rl only: with the oracle's solver libraries (Pinocchio,
placo, CasADi, proxsuite) unimportable, the stand env steps, a run trains, evaluates and rolls
out in sim2sim, and an oracle command says in one line what to install."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from a2cf_mb.cli import ORACLE_LIBRARIES

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = textwrap.dedent(
    """
    import contextlib, importlib.abc, io, json, sys

    BLOCKED = set(sys.argv[2].split(","))

    class Blocker(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            top = name.split(".")[0]
            if top in BLOCKED:  # what a missing package raises
                raise ModuleNotFoundError(f"No module named '{top}'", name=top)
            return None

    sys.meta_path.insert(0, Blocker())

    import torch
    from a2cf_mb.cli import main
    from rl.envs.config import EnvConfig
    from rl.envs.vec_env import G1VecEnv
    from rl.tasks.registry import get_task

    env = G1VecEnv(EnvConfig(num_envs=2, num_threads=1), get_task("stand"))
    obs, reward, done, _ = env.step(torch.zeros(2, env.num_actions))
    env.close()
    out = sys.argv[1]
    train = main([
        "train", "--task", "stand", "--env-num-envs", "4", "--env-num-threads", "1",
        "--iterations", "1", "--num-steps-per-env", "8", "--out", out, "--run-name", "run",
        "--eval-interval", "1", "--eval-num-envs", "2", "--ppo-num-mini-batches", "2",
        "--ppo-num-learning-epochs", "1", "--model-motion-hidden-dims", "32",
        "--model-critic-hidden-dims", "32", "--model-encoder-hidden-dims", "32",
        "--model-assist-hidden-dims", "16",
    ])
    evaluate = main(["eval", f"{out}/run", "--num-envs", "2", "--num-steps", "5", "--sim2sim"])
    with contextlib.redirect_stderr(io.StringIO()) as err:
        solve = main(["solve-walk"])
    print(json.dumps({
        "reward_shape": list(reward.shape),
        "finite": bool(torch.isfinite(reward).all()),
        "train": train,
        "eval": evaluate,
        "solve_walk": solve,
        "solve_walk_error": err.getvalue(),
        "imported": sorted(BLOCKED & set(sys.modules)),
    }))
    """
)


def test_stand_trains_evaluates_and_rolls_out_without_the_oracle_libraries(tmp_path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    command = [sys.executable, "-c", SCRIPT, str(tmp_path), ",".join(ORACLE_LIBRARIES)]
    done = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["reward_shape"] == [2] and result["finite"]
    assert result["train"] == 0 and result["eval"] == 0
    run = tmp_path / "run"
    assert (run / "checkpoints" / "last.pt").is_file() and (run / "policy.onnx").is_file()
    assert "sim2sim" in json.loads((run / "eval.json").read_text())
    assert result["imported"] == []
    # The oracle itself: one line naming the packages to install, exit code 2.
    assert result["solve_walk"] == 2
    error = result["solve_walk_error"].strip()
    assert len(error.splitlines()) == 1 and "pip install 'pin" in error
    assert "Traceback" not in error
