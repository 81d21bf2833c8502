"""Flips landed by a checkpoint's policy alone from standing (N fresh envs), under the flip
judge's contact margin (0.1 s: a link may touch the ground within 0.1 s of where the reference
puts it down) and under wider ones. The oracle's flip rests its shins on the ground through its
landing crouch (2.82-3.08 s); a robot that rises from that crouch a little later than the
reference grazes the floor with a shin after the window and fails the judge, landed or not.

    python docs/results/backflip_track/judge_margin.py RUN_DIR CHECKPOINT [N] [SEED] [MARGIN...]
"""

from __future__ import annotations

import dataclasses
import json
import sys

from rl.evaluation.alone import rollout_alone
from rl.evaluation.policy import alone_from_checkpoint, one_line_errors
from rl.runs.folder import load_run_config
from rl.tasks.registry import resolve_task

KEYS = ("flips_landed", "full_turns", "touched_down_after_turn", "other_link_on_ground",
        "upright_still_at_end", "success_rate", "turn_rad_mean")  # fmt: skip


def landed(run: str, checkpoint: str, n: int, seed: int, margin_s: float) -> dict:
    task = resolve_task(load_run_config(run))
    judge = dataclasses.replace(task.evaluation, contact_margin_s=margin_s)
    env, policy = alone_from_checkpoint(
        run, checkpoint, n, seed, dataclasses.replace(task, evaluation=judge)
    )
    result = rollout_alone(env, lambda obs: policy(obs["policy"], obs["history"]))
    env.close()
    return {k: round(result["task_metrics"][k], 3) for k in KEYS}


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    with one_line_errors():
        run, checkpoint = sys.argv[1], sys.argv[2]
        n = int(sys.argv[3]) if len(sys.argv) > 3 else 128
        seed = int(sys.argv[4]) if len(sys.argv) > 4 else 20000
        margins = [float(m) for m in sys.argv[5:]] or [0.1, 0.3]
        out = {"run": run, "checkpoint": checkpoint, "num_envs": n, "seed": seed,
               "by_contact_margin_s": {m: landed(run, checkpoint, n, seed, m) for m in margins}}  # fmt: skip
        print(json.dumps(out, indent=1))
