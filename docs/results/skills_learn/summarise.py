"""Summarise the skills-that-learn runs: env steps to each task's assistance-free target, the
curves (``study.png``) and the numbers behind them (``study.json``)."""

from __future__ import annotations

import argparse

from rl.studies.learning import summarise_study


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("runs", nargs="+", help="run folders")
    parser.add_argument("--out", required=True, help="folder for study.json and study.png")
    args = parser.parse_args()
    result = summarise_study(args.runs, args.out)
    for run in result["runs"]:
        reached = run["reached_at_env_steps"]
        print(
            f"{run['run']:<28} target {run['target']:<45} "
            f"{'reached at ' + format(reached, ',') + ' env steps' if reached else 'not reached'}; "
            f"evaluated to {run['evaluated_env_steps']:,} env steps, last survival "
            f"{run['last_survival']}, last {run['metric'] or '-'} {run['last_metric']}"
        )


if __name__ == "__main__":
    main()
