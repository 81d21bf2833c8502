"""Where a flip policy alone fails: N fresh envs from standing (the evaluation's start), the
checkpoint's deterministic policy, no help; per env the step and the termination term that ended
its episode, and along the way the pelvis pitch turned by the robot and by the reference, the
pelvis height of both, and whether the soles touch the ground.

    python docs/results/backflip_track/where_it_fails.py RUN_DIR CHECKPOINT [N]
"""

from __future__ import annotations

import json
import sys
from collections import Counter

import numpy as np
import torch

from rl.evaluation.policy import alone_from_checkpoint, one_line_errors
from rl.runs.folder import load_run_config
from rl.tasks.registry import resolve_task
from rl.tasks.track.library import pitch_increment_rad


def main(run: str, checkpoint: str, n: int) -> dict:
    import rl.envs.vec_env as vec_env

    task = resolve_task(load_run_config(run))
    seen: dict = {}
    any_failure = vec_env.any_failure

    def spy(terms, state):  # the state before the resets, and each term's verdict on it
        seen["state"], seen["terms"] = state, {t.name: t(state) for t in terms}
        return any_failure(terms, state)

    vec_env.any_failure = spy
    env, policy = alone_from_checkpoint(run, checkpoint, n, 20003, task)
    obs, active = env.get_observations(), torch.ones(n, dtype=torch.bool)
    cmd = env.command_gen
    pelvis = cmd.motion.body_quat_w[:, 0].double()  # the reference's pelvis, frame by frame
    ref_turn = torch.cat(
        [torch.zeros(1), (-pitch_increment_rad(pelvis[:-1], pelvis[1:])).float().cumsum(0)]
    )
    last = env.env_state.base_quat_w.clone()
    turned, turned_ref = torch.zeros(n), torch.zeros(n)
    ended: list[dict] = []
    trace = []  # env 0: (t, turn, reference turn, pelvis z, reference z, soles on the ground)
    with torch.inference_mode():
        for step in range(int(env.max_episode_length)):
            actions = policy(obs["policy"], obs["history"])
            obs, _, dones, extras = env.step(torch.cat([actions, torch.zeros(n, 6)], dim=-1))
            s, done = seen["state"], dones.bool()
            turned += torch.where(
                active, -pitch_increment_rad(last.double(), s.base_quat_w.double()).float(), 0.0
            )
            # the frame this step aimed at, counted from the clip's first (standing) frame
            frame = cmd.frame() - cmd._start[cmd.clip]
            turned_ref = torch.where(
                active & ~done, ref_turn[frame.clamp(max=len(ref_turn) - 1)], turned_ref
            )
            last = env.env_state.base_quat_w.clone()  # after the resets: the next step's start
            if active[0]:
                trace.append((round((step + 1) * env.step_dt_s, 2), round(float(turned[0]), 2),
                              round(float(turned_ref[0]), 2), round(float(s.base_pos_w[0, 2]), 2),
                              round(float(s.targets["body_pos_w"][0, 0, 2]), 2),
                              int((s.foot_contact_force_n[0] > 20).sum())))  # fmt: skip
            for i in torch.nonzero(active & done).flatten().tolist():
                ended.append({"env": i, "t_s": round((step + 1) * env.step_dt_s, 2),
                              "time_out": bool(extras["time_outs"][i]),
                              "turn_rad": round(float(turned[i]), 2),
                              "reference_turn_rad": round(float(turned_ref[i]), 2),
                              "terms": [k for k, v in seen["terms"].items() if bool(v[i])]})  # fmt: skip
            active &= ~done
            if not active.any():
                break
    env.close()
    vec_env.any_failure = any_failure
    causes = Counter("+".join(e["terms"]) or "time-out" for e in ended)
    return {
        "run": run, "checkpoint": checkpoint, "num_envs": n, "seed": 20003,
        "end_time_s": {"mean": float(np.mean([e["t_s"] for e in ended])),
                       "min": min(e["t_s"] for e in ended), "max": max(e["t_s"] for e in ended)},
        "turn_rad_mean": float(np.mean([e["turn_rad"] for e in ended])),
        "reference_turn_at_end_rad_mean": float(np.mean([e["reference_turn_rad"] for e in ended])),
        "ended_by": dict(causes),
        "per_env": ended,
        "env0_trace (t s, turn, ref turn, pelvis z, ref z, soles down)": trace[85:],
    }  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    with one_line_errors():
        n = int(sys.argv[3]) if len(sys.argv) > 3 else 32
        print(json.dumps(main(sys.argv[1], sys.argv[2], n), indent=1))
