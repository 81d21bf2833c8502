"""Where the sim2sim gap of a flip policy comes from: the exported policy of RUN_DIR (a run
folder with ``policy.onnx`` and ``policy.json``, e.g. ``../export_checkpoint.sh``'s output) in
sim2sim as built (1 kHz explicit PD, URDF collision meshes, elliptic cone, Euler), then with
one of its settings set back to the training physics' at a time (pyramidal cone, implicitfast,
the training env's link primitives), then all three, then without any floor contact of the
shins (the knee links: does the policy lean on them?). The same N robots (seed), each with its own
draw of the task's randomisation and observation noise, judged by the task's flip judge.
Prints one json object; what stays different in the last row is the actuation (explicit PD at
1 kHz against MuJoCo's implicit position actuators at 200 Hz) and the physics step.

    python docs/results/backflip_track/sim2sim_gap.py RUN_DIR [N] [SEED]
"""

from __future__ import annotations

import dataclasses
import json
import sys

from rl.evaluation.policy import one_line_errors
from rl.evaluation.sim2sim import Sim2SimConfig, run_sim2sim
from rl.runs.folder import load_run_config
from rl.tasks.registry import make_env, resolve_task

KEYS = ("flips_landed", "full_turns", "touched_down_after_turn", "other_link_on_ground",
        "upright_still_at_end", "success_rate", "turn_rad_mean")  # fmt: skip
SHINS = ("left_knee_link", "right_knee_link")
VARIANTS = {
    "sim2sim": {},
    "pyramidal cone": {"cone": "pyramidal"},
    "implicitfast": {"integrator": "implicitfast"},
    "link primitives": {"link_meshes": False},
    "all three": {"cone": "pyramidal", "integrator": "implicitfast", "link_meshes": False},
    "link primitives, shins off the floor": {"link_meshes": False, "links_off_floor": SHINS},
    "shins off the floor": {"links_off_floor": SHINS},
}


def gap(run: str, n: int, seed: int) -> dict:
    task = resolve_task(load_run_config(run))
    env = make_env(task, 1, num_threads=1)
    steps = int(env.max_episode_length)
    env.close()
    out = {}
    for name, change in VARIANTS.items():
        cfg = dataclasses.replace(Sim2SimConfig(num_envs=n, seed=seed), **change)
        metrics = run_sim2sim(run, task, steps, cfg)["task_metrics"]
        out[name] = {k: round(metrics[k], 3) for k in KEYS}
        print(name, out[name], file=sys.stderr, flush=True)
    return out


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    with one_line_errors():
        run = sys.argv[1]
        n = int(sys.argv[2]) if len(sys.argv) > 2 else 128
        seed = int(sys.argv[3]) if len(sys.argv) > 3 else 20000
        print(json.dumps({"run": run, "num_envs": n, "seed": seed, "variants": gap(run, n, seed)},
                         indent=1))  # fmt: skip
