"""How far the PD follower of the flip turns at zero action, with and without the oracle's
feed-forward (``--task-action-feedforward``): 4 robots start on the reference 8 frames before
its crouch (reference state initialisation, frame 88 of the held flip), no help, terminations
off, 70 policy steps (1.4 s: crouch, jump, air and the touch-down). Prints the pitch turned
(mean over the 4 robots) and the pelvis height every 5 steps, for: the PD alone (targets
q_ref), the velocity feed-forward only (kd/kp qd_ref), the torque feed-forward only
(tau_ref/kp, the TO's torques) and both (the option).

    python docs/results/backflip_track/probe_feedforward.py [ARTIFACT] [START_FRAME]
"""

from __future__ import annotations

import dataclasses
import json
import sys
import types

import torch

from rl.tasks.registry import make_env
from rl.tasks.track.library import pitch_increment_rad
from rl.tasks.track.task import adapt_to_references, track_task

ART = sys.argv[1] if len(sys.argv) > 1 else "runs/backflip_track/oracle"
START = int(sys.argv[2]) if len(sys.argv) > 2 else 88
VARIANTS = {"pd": (False, False), "velocity": (True, False), "torque": (False, True),
            "velocity+torque": (True, True)}  # fmt: skip


def turn(velocity: bool, torque: bool, n: int = 4, steps: int = 70) -> list[tuple]:
    task = adapt_to_references(track_task((ART,)))
    task = dataclasses.replace(task, terminations=(), action_feedforward=velocity or torque)
    env = make_env(task, n, num_threads=1, seed=5)
    cmd, motion = env.command_gen, env.motion
    env.for_evaluation()
    env.set_assist_enabled(False)
    sample = cmd._sample

    def from_start(self, env_ids):  # the evaluation's first frame, moved to START
        sample(env_ids)
        self.start_frame[env_ids] = self._start[self.clip[env_ids]] + START

    cmd._sample = types.MethodType(from_start, cmd)
    full = motion.feedforward_rad
    motion.feedforward_rad = lambda qd, tau: full(qd * velocity, tau * torque)
    env.reset_envs(torch.arange(n))
    last, turned, rows = env.env_state.base_quat_w.clone(), torch.zeros(n), []
    for k in range(steps):
        env.step(torch.zeros(n, 35))
        s = env.env_state
        turned -= pitch_increment_rad(last.double(), s.base_quat_w.double()).float()
        last = s.base_quat_w.clone()
        if k % 5 == 4:
            rows.append(
                (k + 1, round(float(turned.mean()), 2), round(float(s.base_pos_w[:, 2].mean()), 2))
            )
    env.close()
    return rows


if __name__ == "__main__":
    out = {}
    for name, (velocity, torque) in VARIANTS.items():
        rows = turn(velocity, torque)
        out[name] = {"max_turn_rad": max(r[1] for r in rows), "(step, turn rad, pelvis z m)": rows}
        print(name, json.dumps(out[name]), flush=True)
