"""Summarise the A2CF lifecycle study: env steps to each task's assistance-free target per run and
per variant (mean, spread, ratio to the baseline) in ``study.json``/``study.png``, and one
lifecycle figure per task (bound, applied force, helped and alone skill, evaluations alone)."""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

from rl.studies.learning import lifecycle_figure, run_summary, summarise_study


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("runs", nargs="+", help="run folders")
    parser.add_argument("--out", required=True, help="folder for study.json, study.png, figures")
    args = parser.parse_args()
    out = Path(args.out)
    result = summarise_study(args.runs, out)
    by_task: dict[str, list[str]] = defaultdict(list)
    for run in args.runs:
        by_task[run_summary(run)["task"]].append(run)
    for task, runs in by_task.items():
        lifecycle_figure(runs, out / f"lifecycle_{task}.png", title=f"A2CF lifecycle: {task}")
    for group in result["groups"]:
        ratio = group["ratio_to_baseline"]
        mean = group["env_steps_to_target_mean"]
        print(
            f"{group['group']:<24} reached {group['reached']:<4} "
            f"mean {'-' if mean is None else format(mean / 1e6, '.2f') + ' M':<8} "
            f"ratio to baseline {'-' if ratio is None else format(ratio, '.2f')}; per seed "
            f"{group['env_steps_to_target']}, evaluated to {group['evaluated_env_steps']}"
        )


if __name__ == "__main__":
    main()
