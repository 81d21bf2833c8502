"""Make a committed policy bundle deploy alone without its checkpoint (issue 55): rewrite its
``policy.json`` in format 3 (model, episode and observation-noise facts) from an env of the run's
task, and write a tracking policy's ``reference.npz``; the ONNX file is kept as it is.

Usage::

    python docs/results/refresh_bundles.py BUNDLE RUN_DIR [REFERENCE ...] [--policy-obs-of TASK]

``RUN_DIR`` holds the run's ``config.json`` (committed beside the bundle, e.g.
``walk_flat/walkflat_a2cf_warm_yaw2_128_s0`` for ``walkflat_a2cf_warm_yaw2_128_s0_it5800``);
``REFERENCE``: the references to use in place of the run's, where those were never committed (the
flip's oracle: ``a2cf-mb solve-backflip --oracle-out DIR`` rebuilds it). The bundle is refused
when today's task gives the policy other inputs than it was trained with, or the reference's
feed-forward torques differ from the bundle's (:func:`rl.agents.export.refresh_bundle`).
``--policy-obs-of TASK``: the policy observation group of registered task TASK in place of
today's recipe's, for a policy trained before its task's observations changed (the walk-flat
policies of Dec 7 read the pelvis velocity as the stand's do; today's walk-flat actor does not).
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys

from rl.agents.export import refresh_bundle
from rl.evaluation.policy import one_line_errors
from rl.runs.folder import load_run_config, read_config_file
from rl.tasks.registry import get_task, make_env, resolve_task


def main(argv: list[str]) -> None:
    """Refresh one bundle (see the module docstring)."""
    if len(argv) < 2:
        sys.exit(__doc__)
    obs_of = ""
    if "--policy-obs-of" in argv:
        at = argv.index("--policy-obs-of")
        obs_of, argv = argv[at + 1], argv[:at] + argv[at + 2 :]
    bundle, run_dir, *references = argv
    cfg = load_run_config(run_dir)
    if references:
        cfg = dataclasses.replace(cfg, reference=tuple(references))
    task = resolve_task(cfg)
    if obs_of:
        policy = get_task(obs_of).observations.policy
        task = dataclasses.replace(
            task, observations=dataclasses.replace(task.observations, policy=policy)
        )
    _require_same_episode(run_dir, task)
    env = make_env(task, 1, num_threads=1, **_env_fields(cfg))
    with contextlib.closing(env):
        description = refresh_bundle(bundle, env)
    extra = f", {description['reference']['file']}" if "reference" in description else ""
    print(f"{bundle}: policy.json ({description['format']}){extra}")


EPISODE_KEYS = ("terminations", "initial_state", "episode_length_s", "randomization", "pushes",
                "scene", "actions_around_reference", "action_feedforward", "drift_free_phases")  # fmt: skip
"""The saved task's entries that the bundle's model and episode facts come from."""


def _require_same_episode(run_dir: str, task) -> None:
    """Refuse a task whose episode (start, end, scene, action law) is not the run's saved one."""
    saved = read_config_file(run_dir, ("task",))["task"]
    today = task.to_json_dict()
    changed = [k for k in EPISODE_KEYS if _differs(saved.get(k), today.get(k))]
    if changed:
        raise ValueError(
            f"{run_dir}: today's task differs from the run's in {', '.join(changed)}: the "
            "bundle's facts would not be the training's"
        )


def _differs(saved, today) -> bool:
    """The saved entry differs from today's; a field the run's version had not yet (absent from
    its config) is not a difference: it ran with what is today's default."""
    if saved is None:
        return False
    if isinstance(saved, dict) and isinstance(today, dict):
        return any(_differs(v, today.get(k)) for k, v in saved.items())
    if isinstance(saved, list) and isinstance(today, list) and len(saved) == len(today):
        return any(_differs(a, b) for a, b in zip(saved, today, strict=True))
    return saved != today


def _env_fields(cfg) -> dict:
    """The run's env settings that shape the policy's interface (history, action clip, noise)."""
    return {
        "history_length": cfg.env.history_length,
        "clip_actions": cfg.env.clip_actions,
        "decimation": cfg.env.decimation,
        "noise": cfg.env.noise,
    }


if __name__ == "__main__":
    with one_line_errors():
        main(sys.argv[1:])
