"""A2CF's early lag on walk-flat, over seeds: each run's 32-env evaluations alone (survival with
pushes, velocity error) averaged over windows of env steps, A2CF beside the baseline of the same
seed, and the difference per seed. The help of the default curriculum ends at iteration 200
(0.61 M env steps), so every window here is after it.

    python docs/results/walk_flat/early_lag.py RUN_PARENT > early_lag.json

RUN_PARENT holds ``walkflat_baseline_128_s<seed>`` and ``walkflat_a2cf_warm_128_s<seed>``, and the
controls: ``walkflat_a2cf_warm_ratio_128_s0`` (the ratio fix), ``walkflat_a2cf_warm_anneal1_128_s2``
(help for one iteration only: everything A2CF brings but the help), ``walkflat_a2cf_anneal1_128_s2``
(the same without the warm start) and ``walkflat_no-pi_warm_128_s0`` (the paper's ablation); a pair
counts where both runs reach the window's end.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

WINDOWS_M = ((0.6, 1.6), (1.6, 2.6), (2.6, 4.0))  # env steps [M], evaluations with lo < x <= hi
VARIANTS = ("a2cf_warm", "a2cf_warm_ratio", "a2cf_warm_anneal1", "a2cf_anneal1", "no-pi_warm")
RUN_NAME = re.compile(rf"walkflat_(baseline|{'|'.join(VARIANTS)})_128_s\d+")  # the study's runs


def evaluations(run: Path) -> list[tuple[float, float, float]]:
    """(env steps [M], survival [-], velocity error [m/s]) of each 32-env evaluation of ``run``."""
    rows = []
    for line in (run / "evals.jsonl").read_text().splitlines():
        e = json.loads(line)
        rows.append((e["env_steps"] / 1e6, e["survival_fraction"],
                     e["task_metrics"]["lin_vel_error_mps"]))  # fmt: skip
    return rows


def window_means(rows: list[tuple[float, float, float]]) -> list[dict | None]:
    """Mean survival and velocity error per window; None where the run has not reached its end."""
    reached = max((r[0] for r in rows), default=0.0)
    out = []
    for lo, hi in WINDOWS_M:
        inside = [r for r in rows if lo < r[0] <= hi]
        if reached < hi - 0.31 or not inside:  # the last evaluation within one interval of the end
            out.append(None)
            continue
        out.append({"survival": round(sum(r[1] for r in inside) / len(inside), 3),
                    "lin_vel_error_mps": round(sum(r[2] for r in inside) / len(inside), 3),
                    "evaluations": len(inside)})  # fmt: skip
    return out


def main(parent: Path) -> dict:
    runs = sorted(
        p
        for p in parent.glob("walkflat_*_128_s*")
        if RUN_NAME.fullmatch(p.name) and (p / "evals.jsonl").is_file()
    )
    table = {p.name: window_means(evaluations(p)) for p in runs}
    pairs = []
    for name in table:
        m = re.fullmatch(rf"walkflat_({'|'.join(VARIANTS)})_128_s(\d+)", name)
        base = f"walkflat_baseline_128_s{m.group(2)}" if m else None
        if base not in table:
            continue
        diffs = []
        for a, b in zip(table[name], table[base], strict=True):
            diffs.append(None if a is None or b is None else {
                "survival": round(a["survival"] - b["survival"], 3),
                "lin_vel_error_mps": round(a["lin_vel_error_mps"] - b["lin_vel_error_mps"], 3)})  # fmt: skip
        pairs.append({"a2cf": name, "baseline": base, "a2cf_minus_baseline": diffs})
    return {"windows_m_env_steps": WINDOWS_M, "runs": table, "pairs": pairs}


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    if not any(RUN_NAME.fullmatch(p.name) for p in Path(sys.argv[1]).glob("walkflat_*")):
        sys.exit(f"{sys.argv[1]} holds no walkflat_<baseline|a2cf_warm>_128_s<seed> run; give "
                 "the runs' parent folder, e.g. runs/walk_flat")  # fmt: skip
    print(json.dumps(main(Path(sys.argv[1])), indent=1))
