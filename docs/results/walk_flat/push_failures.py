"""Where a policy alone falls under pushes (walk-flat, stand): one episode of N fresh envs (seed
20001, not used in training or in the run's evaluations) with the task's pushes and again
without them; per fall, the step, the command it was following (walk), the seconds since that
env's last push and that push's kick in the robot's frame (the pelvis velocity change over the
step: forward +x, left +y); the share of backward kicks among all kicks and among the falls';
and per kick that was followed by another kick or a fall, whether a foot left the ground within
0.5 s (a recovery step) and whether the robot fell, split into backward kicks and the others.

    python docs/results/walk_flat/push_failures.py RUN_DIR CHECKPOINT [N] > push_failures.json
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections import Counter

import torch

from rl.evaluation.policy import alone_from_checkpoint, one_line_errors
from rl.runs.folder import load_run_config
from rl.tasks.registry import resolve_task


def falls(run: str, checkpoint: str, n: int, pushes: bool) -> dict:
    task = resolve_task(load_run_config(run))
    if not pushes:
        task = dataclasses.replace(task, pushes=dataclasses.replace(task.pushes, enabled=False))
    env, policy = alone_from_checkpoint(run, checkpoint, n, 20001, task)
    obs, active, rows = env.get_observations(), torch.ones(n, dtype=torch.bool), []
    since_push = torch.full((n,), float("nan"))  # nan: not pushed yet in this episode
    kick, kicks = torch.zeros(n, 2), []  # each env's last kick; every kick while in its episode
    kick_step, stepped, answers = torch.full((n,), -1), torch.zeros(n, dtype=torch.bool), Counter()
    with torch.inference_mode():
        for step in range(int(env.max_episode_length)):
            command = env.command[:, :3].clone()
            timer = env.pushes.timer_s.clone()
            before = env.env_state.base_lin_vel_b[:, :2].clone()
            actions = policy(obs["policy"], obs["history"])
            obs, _, dones, extras = env.step(torch.cat([actions, torch.zeros(n, 6)], dim=-1))
            # the timer was redrawn: a kick this step (a reset redraws it too: not a kick)
            pushed = (env.pushes.timer_s > timer) & ~dones.bool()
            since_push = torch.where(pushed, 0.0, since_push + env.step_dt_s)
            change = env.env_state.base_lin_vel_b[:, :2] - before
            kicks += change[pushed & active].tolist()
            fell = dones.bool() & active & ~extras["time_outs"].bool()
            # a kick's answer: closed by the next kick or a fall (one still open at the end is not)
            for i in torch.nonzero((pushed & active | fell) & (kick_step >= 0)).flatten().tolist():
                way = "backward" if kick[i, 0] < -0.2 else "other"
                answers[f"{way} kick, {'stepped' if stepped[i] else 'no step'}, "
                        f"{'fell' if fell[i] else 'stood'}"] += 1  # fmt: skip
                kick_step[i] = -1
            kick = torch.where(pushed.unsqueeze(-1), change, kick)
            kick_step = torch.where(pushed & active, step, kick_step)
            stepped &= ~pushed
            soon = (kick_step >= 0) & (step - kick_step <= round(0.5 / env.step_dt_s))
            stepped |= soon & (env.env_state.foot_contact_force_n < 20.0).any(dim=-1)
            for i in torch.nonzero(fell).flatten().tolist():
                rows.append({"step": step, "command": [round(float(c), 2) for c in command[i]],
                             "s_since_last_push": None if since_push[i].isnan()
                             else round(float(since_push[i]), 2),
                             "last_kick_b_mps": [round(float(k), 2) for k in kick[i]]})  # fmt: skip
            active &= ~dones.bool()
            if not active.any():
                break
    env.close()
    backward = [k[0] < -0.2 for k in kicks]
    pushed_falls = [r for r in rows if r["s_since_last_push"] is not None]
    pushed_falls = [r for r in pushed_falls if r["s_since_last_push"] < 3.0]
    return {"pushes": pushes, "num_envs": n, "falls": len(rows), "survival": 1 - len(rows) / n,
            "kicks": len(kicks),
            "backward_kicks_share (x < -0.2 m/s)": sum(backward) / max(1, len(kicks)),
            "falls_within_3_s_of_a_kick": len(pushed_falls),
            "of_them_after_a_backward_kick": sum(r["last_kick_b_mps"][0] < -0.2
                                                 for r in pushed_falls),
            "kicks answered (a foot up within 0.5 s) and their outcome": dict(sorted(answers.items())),
            "per_fall": rows}  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    with one_line_errors():
        run, checkpoint = sys.argv[1], sys.argv[2]
        n = int(sys.argv[3]) if len(sys.argv) > 3 else 128
        result = {"run": run, "checkpoint": checkpoint, "seed": 20001,
                  "with_pushes": falls(run, checkpoint, n, True),
                  "without_pushes": falls(run, checkpoint, n, False)}  # fmt: skip
        print(json.dumps(result, indent=1))
