"""Does a bundle alone reproduce the training env? A committed policy bundle played by the
standalone runner (``a2cf_mb/deploy/run_bundle.py``, MuJoCo + onnxruntime + numpy) beside the
training env's evaluation of the same ONNX policy (``rl.evaluation.alone.rollout_alone``, the env
built from the run's committed config), on the same number of robots (issue 55).

Usage::

    python docs/results/bundle_agreement.py BUNDLE RUN_DIR [REFERENCE ...] [--num-envs 32]
        [--policy-obs-of TASK] [--out FILE.json]

Two rows per figure: ``quiet`` (no noise, no randomisation on either side: the same episodes, so
the two should agree to rounding), and ``as trained`` (observation and start noise, domain
randomisation and pushes on both sides, each from its own draws: the two agree within the spread
of 32 draws). ``REFERENCE`` and ``--policy-obs-of`` as in ``refresh_bundles.py``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import sys
from pathlib import Path

import torch

from a2cf_mb.deploy.run_bundle import run_bundle
from rl.agents.export import OnnxMotionPolicy
from rl.envs.task_schema import quiet
from rl.evaluation.alone import rollout_alone
from rl.evaluation.policy import one_line_errors
from rl.runs.folder import load_run_config
from rl.tasks.registry import get_task, make_env, resolve_task

METRICS = ("survival_fraction", "mean_episode_length_steps", "joint_error_rad",
           "pelvis_pos_error_m", "body_pos_error_m", "body_rel_error_m", "lin_vel_error_mps",
           "yaw_rate_error_rps")  # fmt: skip


def _option(argv: list[str], name: str, default: str) -> tuple[str, list[str]]:
    """The value of ``--name VALUE`` in ``argv`` and ``argv`` without it."""
    if name not in argv:
        return default, argv
    at = argv.index(name)
    return argv[at + 1], argv[:at] + argv[at + 2 :]


def training_env_result(bundle: Path, task, cfg, num_envs: int, num_steps: int) -> dict:
    """The training env's evaluation of the bundle's ONNX policy (``num_steps`` 0: the cap)."""
    env = make_env(task, num_envs, num_threads=1, history_length=cfg.env.history_length,
                   clip_actions=cfg.env.clip_actions, seed=1)  # fmt: skip
    onnx = OnnxMotionPolicy(bundle / "policy.onnx")

    def policy(obs):
        return torch.from_numpy(onnx(obs["policy"].numpy(), obs["history"].numpy()))

    with contextlib.closing(env):
        return rollout_alone(env, policy, num_steps)


def _row(result: dict) -> dict:
    metrics = {**result, **result.get("task_metrics", {})}
    return {k: metrics[k] for k in METRICS if k in metrics}


def main(argv: list[str]) -> None:
    """Compare (see the module docstring)."""
    num_envs, argv = _option(argv, "--num-envs", "32")
    obs_of, argv = _option(argv, "--policy-obs-of", "")
    out, argv = _option(argv, "--out", "")
    if len(argv) < 2:
        sys.exit(__doc__)
    bundle, run_dir, *references = argv
    bundle, n = Path(bundle), int(num_envs)
    cfg = load_run_config(run_dir)
    if references:
        cfg = dataclasses.replace(cfg, reference=tuple(references))
    task = resolve_task(cfg)
    if obs_of:
        policy_group = get_task(obs_of).observations.policy
        task = dataclasses.replace(
            task, observations=dataclasses.replace(task.observations, policy=policy_group)
        )
    facts = json.loads((bundle / "policy.json").read_text())
    steps, script = facts["episode"]["max_steps"], ()
    if hasattr(task.evaluation, "scripted"):  # a walk: both sides follow its scripted commands
        task = dataclasses.replace(task, evaluation=task.evaluation.scripted())
        script = tuple((seg.duration_s, seg.command) for seg in task.evaluation.command_script)
        steps = round(sum(d for d, _ in script) * facts["control"]["policy_rate_hz"])
    quiet_runner = dict(noise=False, randomize=False, pushes=False)
    rows = {
        "quiet": {
            "training_env": _row(training_env_result(bundle, quiet(task), cfg, n, steps)),
            "runner": _row(run_bundle(bundle, n, steps, script=script, **quiet_runner)),
        },
        "as_trained": {
            "training_env": _row(training_env_result(bundle, task, cfg, n, steps)),
            "runner": _row(run_bundle(bundle, n, steps, seed=1, script=script)),
        },
    }
    print(f"{bundle} ({n} robots, {steps} steps)")
    print(
        f"{'':<28}{'quiet: training':>16}{'runner':>10}{'as trained: training':>22}{'runner':>10}"
    )
    for key in METRICS:
        values = [rows[s][side].get(key) for s in rows for side in ("training_env", "runner")]
        if all(v is not None for v in values):
            print(
                f"{key:<28}{values[0]:>16.4f}{values[1]:>10.4f}{values[2]:>22.4f}{values[3]:>10.4f}"
            )
    if out:
        Path(out).write_text(json.dumps({"bundle": str(bundle), "num_envs": n, **rows}, indent=2))


if __name__ == "__main__":
    with one_line_errors():
        main(sys.argv[1:])
