"""Stand with and without the velocity estimate: survival alone under the task's pushes against
env steps, each run's 32-env evaluations (line) and its checkpoints on 128 fresh envs of seed
20000 (markers), with the 90 % target.

    python docs/results/stand_judge/plot.py RUN_OR_RECORD... --out docs/results/stand_judge/velocity.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def rows(path: Path, num_envs: int) -> list[tuple[float, float]]:
    """(env steps [M], survival) of the evaluations in ``path`` made on ``num_envs`` envs."""
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        r = json.loads(line)
        if r.get("num_envs") == num_envs:
            out.append((r["env_steps"] / 1e6, r["survival_fraction"]))
    return sorted(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, run in enumerate(args.runs):
        color = f"C{i}"
        line = rows(run / "evals.jsonl", 32)
        if not line:
            raise SystemExit(
                f"{run / 'evals.jsonl'}: no 32-env evaluations (a run folder made by train?)"
            )
        ax.plot(*zip(*line, strict=True), color=color, lw=1.2, label=f"{run.name}: 32 envs")
        marks = rows(run / "evals_checkpoints.jsonl", 128)
        if marks:
            ax.plot(
                *zip(*marks, strict=True),
                "o",
                color=color,
                ms=5,
                label=f"{run.name}: 128 fresh envs",
            )
    ax.axhline(0.9, color="k", ls="--", lw=0.8)
    ax.axvline(3.0, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("env steps [M]")
    ax.set_ylabel("survival alone, pushes 0.5 m/s")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(0, 3.1)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("stand: the policy reading the pelvis velocity (since Dec 6) against without")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
