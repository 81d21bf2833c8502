"""Which links other than the soles touch the ground along a flip reference played exactly (the
robot put on each frame, with the tracking task's floor offset), and along a policy's episodes
(the checkpoint's deterministic policy alone from standing, 32 fresh envs of the evaluation's
seed): the first such link and its time, where the reference keeps that link off the ground
(within the judge's margin, 0.1 s): the contacts the flip judge counts as a failed landing.

    python docs/results/backflip_track/reference_contacts.py ARTIFACT [RUN_DIR CHECKPOINT]
"""

from __future__ import annotations

import json
import sys
from collections import Counter

import torch

from rl.envs.task_schema import quiet
from rl.tasks.registry import get_task, make_env, with_references


def reference_contacts(artifact: str) -> list[tuple[int, float, list[str]]]:
    task = quiet(with_references(get_task("track"), (artifact,), ""))
    env = make_env(task, 1, num_threads=1)
    cmd, lay, names = env.command_gen, env.layout, env.env_state.contact_body_names
    hits = []
    for f in range(int(cmd.library.length[0])):
        qpos = cmd.library.qpos[f].copy()
        qpos[2] += float(cmd.z_offset_m[0])  # the floor offset of the episode's start
        env.state[0, lay.qpos] = qpos
        env.state[0, lay.qvel] = 0.0
        env.physics.refresh_sensors(torch.arange(1))
        down = env._read_state().body_ground_contact[0]
        if down.any():
            hits.append((f, round(f * env.step_dt_s, 2), [names[i] for i in torch.nonzero(down).flatten().tolist()]))  # fmt: skip
    env.close()
    return hits


def policy_contacts(run: str, checkpoint: str, n: int = 32) -> dict:
    from rl.evaluation.policy import alone_from_checkpoint

    env, policy = alone_from_checkpoint(run, checkpoint, n, 10000)
    obs, active, first = env.get_observations(), torch.ones(n, dtype=torch.bool), {}
    names = env.env_state.contact_body_names
    margin = round(0.1 / env.step_dt_s)  # the flip judge's contact_margin_s, in frames
    with torch.inference_mode():
        for step in range(int(env.max_episode_length)):
            allowed = env.command_gen.reference_link_contact(names, margin)
            down = env.env_state.body_ground_contact & ~allowed & active[:, None]
            for i, b in torch.nonzero(down).tolist():
                first.setdefault(i, (round(step * env.step_dt_s, 2), names[b]))
            actions = policy(obs["policy"], obs["history"])
            obs, _, dones, _ = env.step(torch.cat([actions, torch.zeros(n, 6)], dim=-1))
            active &= ~dones.bool()
            if not active.any():
                break
    env.close()
    return {"run": run, "checkpoint": checkpoint, "envs_with_another_link_down": len(first),
            "num_envs": n, "first_link": dict(Counter(v[1] for v in first.values())),
            "first_contact_time_s": sorted(v[0] for v in first.values())}  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    from rl.evaluation.policy import one_line_errors

    with one_line_errors():
        hits = reference_contacts(sys.argv[1])
        out = {"artifact": sys.argv[1], "reference_frames_with_another_link_down": len(hits),
               "frames (frame, t s, links)": hits}  # fmt: skip
        if len(sys.argv) > 3:
            out["policy"] = policy_contacts(sys.argv[2], sys.argv[3])
        print(json.dumps(out, indent=1))
