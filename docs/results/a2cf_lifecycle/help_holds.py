"""How much help keeps an untrained dance policy up? The first-episode length of 32 envs whose
motion actions are N(0, 0.5) (PPO's initial policy around the default pose) while a coach's wrench,
clipped to k x eta0, is applied (random mask 0.2, as in training); k = 0 is no help.

    python docs/results/a2cf_lifecycle/help_holds.py ORACLE_DIR 0 1 2 4 8   # the oracle's coach
    python docs/results/a2cf_lifecycle/help_holds.py posture 1 4 10 25       # the posture coach

(``ORACLE_DIR``: ``a2cf-mb solve-dance --out ORACLE_DIR --no-video``.)
"""

from __future__ import annotations

import sys

import torch

from rl.a2cf.warmstart import choose_coach, warmstart_eta0
from rl.tasks.registry import get_task, make_env
from rl.training.config import TrainConfig

NUM_ENVS, STEPS, ACTION_STD = 32, 500, 0.5


def first_episode_length(source: str, scale: float) -> float:
    """Mean first-episode length [policy steps] under the coach ``source`` clipped to
    ``scale`` x eta0 (the oracle's eta0, or the task's for a built-in coach)."""
    torch.manual_seed(0)
    task = get_task("dance")
    env = make_env(task, NUM_ENVS, num_threads=1, seed=7)
    eta0 = warmstart_eta0(TrainConfig(task="dance", warmstart=source), task)
    if eta0 is None:
        eta0 = torch.as_tensor(task.default_assist_bound())
    env.set_assist_bound(eta0 * scale)
    env.set_assist_enabled(scale > 0)
    coach, _ = choose_coach(source, env)
    first = torch.full((NUM_ENVS,), float(STEPS))
    seen = torch.zeros(NUM_ENVS, dtype=torch.bool)
    for step in range(STEPS):
        actions = torch.zeros(NUM_ENVS, env.num_actions)
        actions[:, :29] = ACTION_STD * torch.randn(NUM_ENVS, 29)
        bound = env.assist.bound[env.phase]
        ratio = torch.where(bound > 0, coach(env) / bound.clamp_min(1e-9), 0.0)
        actions[:, 29:] = torch.atanh(ratio.clamp(-0.999, 0.999))
        _, _, dones, _ = env.step(actions)
        new = dones & ~seen
        first[new] = step + 1
        seen |= dones
        if seen.all():
            break
    env.close()
    return float(first.mean())


def main() -> None:
    source, scales = sys.argv[1], [float(k) for k in sys.argv[2:]]
    for scale in scales:
        length = first_episode_length(source, scale)
        print(f"{source} k={scale:g}: mean first-episode length {length:.0f} / {STEPS} steps")


if __name__ == "__main__":
    main()
