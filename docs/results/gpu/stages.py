"""The measuring stages of ``run_gpu_check.sh``: compile, Warp speed, MuJoCo C speed, train rows.

Every figure is appended to a JSON-lines file (``--rows``) the moment it is measured, so a stage
that its time limit cuts off keeps what it had. Times on CUDA are taken with CUDA events around
the timed steps (the GPU's own clock: launch and sync overheads of the host are in the interval
only as far as they delay the GPU) and with the host's clock after a synchronise; on the CPU with
the host's clock alone.

    python3 -u docs/results/gpu/stages.py compile --device cuda --rows results.jsonl
    python3 -u docs/results/gpu/stages.py warp --device cuda --sizes 4096 8192 --rows results.jsonl
    python3 -u docs/results/gpu/stages.py mujoco --num-envs 1024 --rows results.jsonl
    python3 -u docs/results/gpu/stages.py train-rows --run RUN_DIR --rows results.jsonl
    python3 -u docs/results/gpu/stages.py train-rows --row-stage backflip --run RUN_DIR --rows ...
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch


def append_row(path: str, row: dict) -> None:
    """Append one JSON line to ``path`` now (and echo it to the log)."""
    line = json.dumps(row)
    print(line, flush=True)
    if path:
        with open(path, "a") as f:
            f.write(line + "\n")


def timed(device: str, func: Callable[[], None]) -> dict:
    """Seconds of ``func()``: ``wall_s`` on the host's clock after a synchronise and, on CUDA,
    ``cuda_event_s`` between CUDA events recorded before and after it."""
    cuda = device.startswith("cuda")
    if cuda:
        torch.cuda.synchronize()
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
    t0 = time.perf_counter()
    func()
    if not cuda:
        return {"wall_s": time.perf_counter() - t0}
    end.record()
    torch.cuda.synchronize()
    return {"wall_s": time.perf_counter() - t0, "cuda_event_s": start.elapsed_time(end) / 1e3}


def random_actions(env, generator: torch.Generator) -> torch.Tensor:
    """Motion and assist actions of std 0.5 for every env, on the env's device."""
    a = 0.5 * torch.randn(env.num_envs, env.num_actions, generator=generator)
    return a.to(env.device)


def compile_kernels(args: argparse.Namespace) -> None:
    """Build and step every env the later stages use, so Warp compiles (or loads from
    ``WARP_CACHE_PATH``) their kernels once: the task's env as trained and the quiet tasks of the
    parity stage. Two steps each: the second is the first replay of the graph."""
    from rl.envs.task_schema import quiet
    from rl.tasks.registry import get_task, make_env

    quiet_tasks = [(f"{t} (quiet)", quiet(get_task(t))) for t in args.parity_tasks]
    for name, task in [(args.task, get_task(args.task)), *quiet_tasks]:
        start = time.perf_counter()
        env = make_env(task, args.num_envs, backend="warp", device=args.device)
        built = time.perf_counter() - start
        gen = torch.Generator().manual_seed(0)
        first = timed(args.device, lambda env=env, gen=gen: env.step(random_actions(env, gen)))
        second = timed(args.device, lambda env=env, gen=gen: env.step(random_actions(env, gen)))
        env.close()
        append_row(
            args.rows,
            {
                "stage": "compile",
                "task": name,
                "device": args.device,
                "build_s": built,
                "first_step": first,
                "second_step": second,
            },
        )


def warp_speed(args: argparse.Namespace) -> None:
    """Per batch size: the env alone (``G1VecEnv.step`` with random actions, everything of the
    env included) and end to end (rsl-rl's training iterations: policy, env, PPO update)."""
    from rl.envs.config import EnvConfig
    from rl.evaluation.config import AloneEvalConfig
    from rl.training.config import TrainConfig
    from rl.training.runner import build_training, seed_everything

    for n in args.sizes:
        cfg = TrainConfig(
            task=args.task,
            iterations=1 + 1 + args.iterations,
            env=EnvConfig(num_envs=n, backend="warp", device=args.device, seed=0),
            device=args.learner_device,
            eval=AloneEvalConfig(interval=0),
            export_onnx=False,
        )
        seed_everything(0)
        # A folder that outlives the stage: rsl-rl's writer may still flush into it at the end.
        run_dir = Path(args.run_root or tempfile.mkdtemp()) / f"warp_{n}"
        shutil.rmtree(run_dir, ignore_errors=True)
        start = time.perf_counter()
        env, runner, _ = build_training(cfg, run_dir)
        run_dir.mkdir(parents=True)
        built = time.perf_counter() - start
        gen = torch.Generator().manual_seed(0)
        for _ in range(args.warmup_steps):
            env.step(random_actions(env, gen))
        actions = [random_actions(env, gen) for _ in range(args.steps)]

        def steps(env=env, actions=actions) -> None:
            for a in actions:
                env.step(a)

        t = timed(args.device, steps)
        rate = {k.replace("_s", "_env_steps_per_s"): n * args.steps / v for k, v in t.items()}
        append_row(
            args.rows,
            {
                "stage": "warp",
                "what": "env",
                "num_envs": n,
                "steps": args.steps,
                "build_s": built,
                **t,
                **rate,
            },
        )
        runner.learn(1)  # the first iteration allocates the rollout storage: untimed
        for i in range(args.iterations):
            t = timed(args.device, lambda runner=runner: runner.learn(1))
            samples = n * cfg.num_steps_per_env
            rate = {k.replace("_s", "_env_steps_per_s"): samples / v for k, v in t.items()}
            append_row(
                args.rows,
                {
                    "stage": "warp",
                    "what": "end_to_end",
                    "num_envs": n,
                    "iteration": i,
                    "samples": samples,
                    **t,
                    **rate,
                },
            )
        env.close()
        del env, runner
        if args.device.startswith("cuda"):
            torch.cuda.empty_cache()


def mujoco_speed(args: argparse.Namespace) -> None:
    """MuJoCo C (CPU threads) at one batch size: ``G1VecEnv.step`` with random actions."""
    from rl.tasks.registry import make_env

    start = time.perf_counter()
    env = make_env(args.task, args.num_envs, num_threads=args.num_threads)
    built = time.perf_counter() - start
    gen = torch.Generator().manual_seed(0)
    for _ in range(args.warmup_steps):
        env.step(random_actions(env, gen))
    for chunk in range(args.chunks):
        actions = [random_actions(env, gen) for _ in range(args.steps)]

        def steps(env=env, actions=actions) -> None:
            for a in actions:
                env.step(a)

        t = timed("cpu", steps)
        append_row(
            args.rows,
            {
                "stage": "mujoco",
                "num_envs": args.num_envs,
                "chunk": chunk,
                "threads": env.num_threads,
                "steps": args.steps,
                "build_s": built,
                **t,
                "env_steps_per_s": args.num_envs * args.steps / t["wall_s"],
            },
        )
    env.close()


def train_rows(args: argparse.Namespace) -> None:
    """The run's per-iteration rows (``metrics.jsonl``, written live) into the results, under
    ``args.row_stage``, and its evaluations alone (``evals.jsonl``, with the task's metrics: a
    flip's ``flips_landed``) under ``<row_stage>_eval``."""
    path = Path(args.run) / "metrics.jsonl"
    if not path.is_file():
        append_row(args.rows, {"stage": args.row_stage, "error": f"no {path}"})
        return
    for line in path.read_text().splitlines():
        row = json.loads(line)
        scalars = {k: v for k, v in row.items() if not isinstance(v, (dict, list))}
        append_row(args.rows, {"stage": args.row_stage, **scalars})
    evals = Path(args.run) / "evals.jsonl"
    for line in evals.read_text().splitlines() if evals.is_file() else []:
        row = json.loads(line)
        metrics = {**row, **row.get("task_metrics", {})}
        scalars = {k: v for k, v in metrics.items() if not isinstance(v, (dict, list))}
        append_row(args.rows, {"stage": f"{args.row_stage}_eval", **scalars})


def main() -> None:
    """Parse the stage and its sizes, run it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="stage", required=True)
    for name in ("compile", "warp", "mujoco", "train-rows"):
        p = sub.add_parser(name)
        p.add_argument("--rows", default="", help="JSON-lines file the figures are appended to")
        p.add_argument("--task", default="walk-flat", help="registered task")
        p.add_argument("--device", default="cuda", help="Warp device: cpu, cuda or cuda:N")
        p.add_argument("--learner-device", default="", help="torch device of the learner")
        p.add_argument("--num-envs", type=int, default=2, help="envs (compile, mujoco) [-]")
        p.add_argument("--sizes", type=int, nargs="+", default=[4096, 8192], help="envs [-]")
        p.add_argument("--steps", type=int, default=50, help="timed policy steps [-]")
        p.add_argument("--warmup-steps", type=int, default=3, help="untimed steps first [-]")
        p.add_argument("--iterations", type=int, default=2, help="timed iterations (warp) [-]")
        p.add_argument("--chunks", type=int, default=3, help="timed chunks (mujoco) [-]")
        p.add_argument("--num-threads", type=int, default=0, help="MuJoCo C threads; 0 all [-]")
        p.add_argument("--run", default="", help="run folder (train-rows)")
        p.add_argument("--row-stage", default="train", help="stage named in the rows (train-rows)")
        p.add_argument("--run-root", default="", help="folder of the warp stage's run folders")
        p.add_argument("--parity-tasks", nargs="*", default=["stand"], help="quiet (compile)")
    args = parser.parse_args()
    args.learner_device = args.learner_device or ("cuda:0" if "cuda" in args.device else "cpu")
    stages = {
        "compile": compile_kernels,
        "warp": warp_speed,
        "mujoco": mujoco_speed,
        "train-rows": train_rows,
    }
    stages[args.stage](args)


if __name__ == "__main__":
    main()
