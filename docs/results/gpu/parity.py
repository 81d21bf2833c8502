"""Parity figures of the Warp backend against MuJoCo C: max state errors per policy step.

The same quiet task (no pushes, randomisation or noise) on both backends, the MuJoCo C env started
from the Warp env's (float32) state, the same random actions (motion and assist) for ``--steps``
policy steps; then world 0 of a stand pair gets a pelvis wrench that world 1 (same state) does
not, and the base acceleration it causes is compared. Writes a JSON of the figures.

On ``--device cuda`` the Warp env's tensors are on the GPU and the MuJoCo C env's on the host:
every comparison is made on host copies (:func:`max_abs_diff`), and what is written into an env
is moved to that env's device first.

    python docs/results/gpu/parity.py --device cpu --out parity_cpu.json
    python docs/results/gpu/parity.py --device cuda --num-envs 64 --out parity_cuda.json
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import torch

from rl.envs.task_schema import quiet
from rl.tasks.registry import make_env


def pair(task: str, num_envs: int, device: str):
    """(MuJoCo C env, Warp env) of the quiet ``task`` at the Warp env's start state."""
    warp = make_env(quiet_task(task), num_envs, backend="warp", device=device)
    c = make_env(quiet_task(task), num_envs, num_threads=2)
    lay = c.layout
    c.state[:, lay.qpos] = warp.physics.qpos.double().cpu().numpy()
    c.state[:, lay.qvel] = warp.physics.qvel.double().cpu().numpy()
    return c, warp


def max_abs_diff(a: torch.Tensor, b: torch.Tensor) -> float:
    """max |a - b| of two tensors of one shape, on any devices, compared in float64 on the host."""
    return float((a.detach().cpu().double() - b.detach().cpu().double()).abs().max())


def quiet_task(name: str):
    """The registered task without pushes, randomisation or observation noise."""
    from rl.tasks.registry import get_task

    return quiet(get_task(name))


def trajectory_errors(
    task: str, num_envs: int, steps: int, device: str, on_row: Callable[[dict], None] | None = None
) -> dict:
    """Per step: max |dqpos|, |dqvel|, |dreward|, |dfoot force| between the backends; each step's
    row goes to ``on_row`` as soon as it is measured (a run cut off keeps the rows it had)."""
    c, warp = pair(task, num_envs, device)
    gen = torch.Generator().manual_seed(7)
    rows = []
    for _ in range(steps):
        actions = 0.3 * torch.randn(num_envs, 35, generator=gen)
        _, rew_c, done_c, _ = c.step(actions)
        _, rew_w, done_w, _ = warp.step(actions)
        rows.append(
            {
                "qpos": max_abs_diff(c.physics.qpos, warp.physics.qpos),
                "qvel": max_abs_diff(c.physics.qvel, warp.physics.qvel),
                "reward": max_abs_diff(rew_c, rew_w),
                "foot_force_n": max_abs_diff(
                    c.env_state.foot_contact_force_n, warp.env_state.foot_contact_force_n
                ),
                "dones_equal": bool(torch.equal(done_c.cpu(), done_w.cpu())),
            }
        )
        if on_row is not None:
            on_row({"stage": "parity", "task": task, "step": len(rows) - 1, **rows[-1]})
    c.close()
    warp.close()
    worst = {k: max(r[k] for r in rows) for k in ("qpos", "qvel", "reward", "foot_force_n")}
    return {"per_step": rows, "max": worst, "dones_equal": all(r["dones_equal"] for r in rows)}


def wrench_errors(device: str) -> dict:
    """Base acceleration [m/s^2, rad/s^2] caused by a pelvis wrench on both backends."""
    c, warp = pair("stand", 2, device)
    wrench_w = torch.tensor([[60.0, -40.0, 80.0, 6.0, 4.0, -5.0], [0.0] * 6])
    acc = {}
    for name, env in (("mujoco", c), ("warp", warp)):  # set_controls takes its env's device's
        env.physics.qpos[1] = env.physics.qpos[0]
        env.physics.qvel[1] = env.physics.qvel[0]
        env.physics.set_controls(env.motion.stand_rad.expand(2, -1), wrench_w.to(env.device))
        env.physics.step()
        qvel = env.physics.qvel.double().cpu()
        acc[name] = ((qvel[0, :6] - qvel[1, :6]) / env.step_dt_s).tolist()
    c.close()
    warp.close()
    diff = max(abs(a - b) for a, b in zip(acc["mujoco"], acc["warp"], strict=True))
    return {"base_acc": acc, "max_abs_diff": diff}


def main() -> None:
    """Parse the flags, measure, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", help="Warp device: cpu, cuda or cuda:N")
    parser.add_argument("--num-envs", type=int, default=4, help="worlds per task [-]")
    parser.add_argument("--steps", type=int, default=10, help="policy steps compared [-]")
    parser.add_argument("--out", default="", help="JSON file for the figures")
    parser.add_argument(
        "--tasks", nargs="+", default=["stand", "dance"], help="registered tasks compared"
    )
    parser.add_argument("--rows", default="", help="JSON-lines file each step's row is added to")
    args = parser.parse_args()

    def on_row(row: dict) -> None:
        print(json.dumps(row), flush=True)
        if args.rows:
            with open(args.rows, "a") as f:
                f.write(json.dumps(row) + "\n")

    start = time.perf_counter()
    figures = {
        "device": args.device,
        "num_envs": args.num_envs,
        "tasks": {
            t: trajectory_errors(t, args.num_envs, args.steps, args.device, on_row)
            for t in args.tasks
        },
        "wrench": wrench_errors(args.device),
    }
    figures["seconds"] = time.perf_counter() - start
    text = json.dumps(figures, indent=1)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)
    summary = {t: r["max"] for t, r in figures["tasks"].items()}
    on_row(
        {
            "stage": "parity",
            "max": summary,
            "wrench_acc_diff": figures["wrench"]["max_abs_diff"],
            "seconds": figures["seconds"],
        }
    )


if __name__ == "__main__":
    main()
