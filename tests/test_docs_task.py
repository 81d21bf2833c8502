"""docs/tasks.md's example task, run as written: one module plus one registration, then trained."""

from __future__ import annotations

import dataclasses
import importlib.util
import re
from pathlib import Path

from rl.tasks.registry import TASKS, register_task
from rl.training.config import TrainConfig
from rl.training.runner import train

DOC = Path(__file__).resolve().parents[1] / "docs" / "tasks.md"


def test_the_documented_task_is_one_module_and_trains(tmp_path) -> None:
    block = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)[0]
    assert len(block.splitlines()) <= 40  # a short example
    path = tmp_path / "squat_task.py"
    path.write_text(block)
    spec = importlib.util.spec_from_file_location("squat_task", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    register_task(module.SQUAT)
    try:
        cfg = TrainConfig(task="squat", mode="a2cf", iterations=2, num_steps_per_env=8,
                          out=str(tmp_path), run_name="squat", export_onnx=False)  # fmt: skip
        cfg = dataclasses.replace(
            cfg, env=dataclasses.replace(cfg.env, num_envs=4, num_threads=1),
            eval=dataclasses.replace(cfg.eval, interval=0),
        )  # fmt: skip
        result = train(cfg, verbose=False)
        assert result.iterations_done == 2
        rows = result.metrics["iterations"]
        assert len(rows) == 2 and rows[-1]["mean_step_reward"] is not None
    finally:
        TASKS.pop("squat")
