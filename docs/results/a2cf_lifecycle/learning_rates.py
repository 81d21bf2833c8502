"""The adaptive learning rate of runs, per iteration, from their TensorBoard events
(``Loss/learning_rate``; runs made since it is in ``metrics.json`` have it there too):
``python learning_rates.py RUN... --out learning_rates.json`` writes, per run, the rate every
iteration and its mean and share at rsl-rl's floor (1e-5) before and after iteration 200 (the
schedule's end). The figures of items 2 and 3 of the README come from this file."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from optimal_control.files import atomic_write_json

FLOOR = 1e-5  # rsl-rl's adaptive schedule never goes below it


def rates(run_dir: Path) -> np.ndarray:
    """The run's learning rate per iteration (a clear error for a folder without events)."""
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    if "Loss/learning_rate" not in events.Tags()["scalars"]:
        raise SystemExit(f"{run_dir}: no TensorBoard events with Loss/learning_rate")
    return np.array([e.value for e in events.Scalars("Loss/learning_rate")])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("runs", nargs="+", type=Path, help="run folders with TensorBoard events")
    parser.add_argument("--out", type=Path, required=True, help="JSON file to write")
    args = parser.parse_args()
    result = {}
    for run in args.runs:
        lr = rates(run)
        parts = {"before_200": lr[:200], "from_200": lr[200:]}
        result[run.name] = {
            "iterations": int(lr.size),
            **{f"mean_{k}": float(v.mean()) if v.size else None for k, v in parts.items()},
            **{
                f"at_floor_{k}": float((v <= FLOOR * 1.01).mean()) if v.size else None
                for k, v in parts.items()
            },  # fmt: skip
            "median": float(np.median(lr)),
            "learning_rate": [float(f"{x:.4g}") for x in lr],
        }
        print(f"{run.name:<28} median {result[run.name]['median']:.2e}  "
              f"at the floor {float((lr <= FLOOR * 1.01).mean()):.0%}")  # fmt: skip
    atomic_write_json(args.out, result)


if __name__ == "__main__":
    main()
