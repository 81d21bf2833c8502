"""Branch a run at one of its kept checkpoints into a new run folder with changed task settings,
to be continued with ``a2cf-mb train --resume``: a staged recipe (train on one setting, then go on
from a checkpoint under another) compared with the original run's own continuation, same seed,
same envs, same env steps.

    python docs/results/walk_flat/branch.py RUN_DIR K NEW_RUN_NAME FIELD=VALUE ...
    a2cf-mb train --resume <parent of RUN_DIR>/NEW_RUN_NAME --iterations 9766

FIELD is a task field as the ``--task-*`` flags name it, dotted (``pushes.train_backward_share``);
VALUE is read as JSON (``0.5``, ``true``, ``[5, 10]``). The new folder gets the run's config with
the overrides added, its provenance (``git.json``, ``git/``), its records up to iteration K and
``model_K.pt`` (also as ``last.pt``, which the resume continues from) and ``branch.json`` (the
parent run, K and the overrides; a study names the run's variant by them). The original run is
not touched.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

from optimal_control.files import atomic_write_json

RECORDS = ("metrics.jsonl", "evals.jsonl", "curriculum.jsonl")  # rows with an "iteration" field
COPIED = ("git.json", "warmstart.json")


def branch(run: Path, k: int, name: str, overrides: dict) -> Path:
    from rl.runs.folder import load_run_config
    from rl.studies.learning import BRANCH_FILE
    from rl.tasks.registry import resolve_task

    if not (run / "config.json").is_file():
        raise SystemExit(
            f"{run} is not a run folder (no config.json); give a training run's folder"
        )
    checkpoint = run / "checkpoints" / f"model_{k}.pt"
    if not checkpoint.is_file():
        kept = sorted(int(p.stem[6:]) for p in (run / "checkpoints").glob("model_*.pt")
                      if p.stem[6:].isdigit())  # fmt: skip
        raise SystemExit(f"{checkpoint} does not exist; kept checkpoints K: {kept}")
    new = run.parent / name
    if new.exists():
        raise SystemExit(f"{new} exists already; pick another NEW_RUN_NAME or remove it")
    with tempfile.TemporaryDirectory(prefix=f".{name}.", dir=run.parent) as tmp:
        part = Path(tmp) / name
        (part / "checkpoints").mkdir(parents=True)
        shutil.copy2(checkpoint, part / "checkpoints" / checkpoint.name)
        shutil.copy2(checkpoint, part / "checkpoints" / "last.pt")
        for f in COPIED:
            if (run / f).is_file():
                shutil.copy2(run / f, part / f)
        if (run / "git").is_dir():
            shutil.copytree(run / "git", part / "git")
        for f in RECORDS:
            if (run / f).is_file():
                # metrics rows count iterations from 0 (row k-1 is the k-th); evaluations are
                # named by completed iterations (the one at k is model_k's)
                last = k - 1 if f == "metrics.jsonl" else k
                rows = [r for r in (run / f).read_text().splitlines(keepends=True)
                        if r.strip() and json.loads(r).get("iteration", -1) <= last]  # fmt: skip
                (part / f).write_text("".join(rows))
        config = json.loads((run / "config.json").read_text())
        config["train"].setdefault("task_overrides", {}).update(overrides)
        config["train"]["run_name"] = name
        atomic_write_json(part / "config.json", config, indent=1)
        provenance = {"run": run.name, "iteration": k, "overrides": overrides}
        atomic_write_json(part / BRANCH_FILE, provenance)
        try:
            task = resolve_task(load_run_config(part))  # an unknown field or a bad value: one line
        except (KeyError, TypeError, ValueError) as err:
            raise SystemExit(f"the overrides {overrides} do not fit the task: {err}") from err
        config["task"] = task.to_json_dict()  # the branch's recipe, as a run saves its own
        atomic_write_json(part / "config.json", config, indent=1)
        part.rename(new)
    return new


if __name__ == "__main__":
    if len(sys.argv) < 4 or not all("=" in a for a in sys.argv[4:]):
        sys.exit(__doc__)
    fields = dict(a.split("=", 1) for a in sys.argv[4:])
    if not sys.argv[2].isdigit():
        sys.exit(f"K must be a checkpoint's iteration (model_K.pt), got '{sys.argv[2]}'")
    try:
        values = {f: json.loads(v) for f, v in fields.items()}
    except json.JSONDecodeError as err:
        sys.exit(
            f"an override value is not JSON ({err}); write e.g. FIELD=0.5 or 'FIELD={{\"a\": 1}}'"
        )
    new = branch(Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3], values)
    print(f"a2cf-mb train --resume {new} --iterations 9766")
