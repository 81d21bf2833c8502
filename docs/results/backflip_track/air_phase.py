"""Why a flip policy alone under-rotates: N fresh envs from standing, the checkpoint's
deterministic policy, no help. Per reference frame from the push-off to the touch-down (mean over
the envs still in their episode): the pelvis pitch rate of the robot and of the reference, the
hip-pitch and knee angles against the reference's (the tuck that sets the body's inertia), and
the share of leg actuators at their torque limit. In flight the body's angular momentum is fixed:
a robot that tucks as deeply as the reference but turns slower left the ground with less of it;
one that turns slower because it tucks less is held back by its legs.

    python docs/results/backflip_track/air_phase.py RUN_DIR CHECKPOINT [N] [FIRST LAST]
"""

from __future__ import annotations

import json
import sys

import numpy as np
import torch

from rl.evaluation.policy import alone_from_checkpoint, one_line_errors
from robots import g1

HIP = [g1.JOINT_NAMES.index(f"{s}_hip_pitch_joint") for s in ("left", "right")]
KNEE = [g1.JOINT_NAMES.index(f"{s}_knee_joint") for s in ("left", "right")]
LEGS = [i for i, name in enumerate(g1.JOINT_NAMES) if any(k in name for k in ("hip", "knee", "ankle"))]  # fmt: skip


def main(run: str, checkpoint: str, n: int, first: int, last: int) -> dict:
    env, policy = alone_from_checkpoint(run, checkpoint, n, 20004)
    cmd = env.command_gen
    obs, active = env.get_observations(), torch.ones(n, dtype=torch.bool)
    rows: dict[int, list[np.ndarray]] = {}
    limit = env.env_state.effort_limit_nm[LEGS]
    with torch.inference_mode():
        for _ in range(int(env.max_episode_length)):
            actions = policy(obs["policy"], obs["history"])
            obs, _, dones, _ = env.step(torch.cat([actions, torch.zeros(n, 6)], dim=-1))
            s = env.env_state
            frame = (cmd.frame() - cmd._start[cmd.clip]).tolist()
            t = s.targets
            ref_rate = t["body_ang_vel_w"][:, 0, 1]  # the reference pelvis' pitch rate (world y)
            q, q_ref = s.joint_pos_rad, t["joint_pos_rad"]
            sat = (s.joint_torque_nm[:, LEGS].abs() >= 0.98 * limit).float().mean(-1)
            for i in torch.nonzero(active & ~dones.bool()).flatten().tolist():
                if first <= frame[i] <= last:
                    rows.setdefault(frame[i], []).append(np.array([
                        float(s.base_ang_vel_b[i, 1]), float(ref_rate[i]),
                        float(q[i, HIP].mean()), float(q_ref[i, HIP].mean()),
                        float(q[i, KNEE].mean()), float(q_ref[i, KNEE].mean()), float(sat[i]),
                    ]))  # fmt: skip
            active &= ~dones.bool()
            if not active.any():
                break
    env.close()
    names = ["pitch_rate", "ref_pitch_rate", "hip_pitch", "ref_hip_pitch", "knee", "ref_knee",
             "legs_at_torque_limit"]  # fmt: skip
    table = [
        {"frame": f, "t_s": round(f * env.step_dt_s, 2), "envs": len(v),
         **{k: round(float(x), 2) for k, x in zip(names, np.mean(v, axis=0), strict=True)}}
        for f, v in sorted(rows.items())
    ]  # fmt: skip
    return {"run": run, "checkpoint": checkpoint, "num_envs": n, "seed": 20004, "frames": table}


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    with one_line_errors():
        n = int(sys.argv[3]) if len(sys.argv) > 3 else 32
        first, last = (int(sys.argv[4]), int(sys.argv[5])) if len(sys.argv) > 5 else (105, 150)
        print(json.dumps(main(sys.argv[1], sys.argv[2], n, first, last), indent=1))
