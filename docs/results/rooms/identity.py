"""Behaviour check for the rl/ reshaping (issue 32): train every task in every mode for 3
iterations on one seed and print a digest of what the run learned and where it stands (weights,
optimisers, env parts, curriculum, random state, evaluation rows; wall times left out).

Run it on two code trees and compare the printed JSON (same digests = bit-identical runs):

    PYTHONPATH=/path/to/old/tree python docs/results/rooms/identity.py OUT_OLD > old.json
    python docs/results/rooms/identity.py OUT_NEW > new.json
    diff old.json new.json
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sys
from pathlib import Path

import torch

FLIP = "runs/backflip_track/oracle"  # a solve-backflip artifact (docs/results/backflip_track)
DANCE = "runs/track_learn/oracle_dance"  # a solve-dance artifact (docs/results/track_learn)
ASSIST_MODES = ("a2cf", "no-pi", "no-id", "no-rm")
CASES: list[tuple[str, list[str]]] = [
    *((f"stand-{m}", ["--task", "stand", "--mode", m]) for m in ("baseline", *ASSIST_MODES)),
    *(
        (f"{t}-{m}", ["--task", t, "--mode", m])
        for t in (
            "walk",
            "walk-flat",
            "walk-paper",
            "backflip",
            "track",
            "dance",
            "dance-paper",
            "dance-joints",
        )
        for m in ("baseline", "a2cf")
    ),
    ("dance-a2cf-warm", ["--task", "dance", "--mode", "a2cf", "--warmstart", DANCE]),
    ("flip-baseline", ["--task", "track", "--reference", FLIP, "--mode", "baseline"]),
    (
        "flip-a2cf-warm",
        ["--task", "track", "--reference", FLIP, "--mode", "a2cf", "--warmstart", FLIP],
    ),
    (
        "flip-coach",
        ["--task", "track", "--reference", FLIP, "--mode", "coach", "--coach-source", FLIP],
    ),
    (
        "stand-a2cf-evalmeasure",
        ["--task", "stand", "--mode", "a2cf", "--curriculum-skill-measure", "evaluation"],
    ),
]
COMMON = [
    "--num-envs",
    "8",
    "--iterations",
    "3",
    "--seed",
    "3",
    "--env-num-threads",
    "1",
    "--num-steps-per-env",
    "8",
    "--eval-interval",
    "2",
    "--eval-num-envs",
    "4",
    "--save-interval",
    "1",
    "--no-export-onnx",
]
SKIP = ("time", "_per_s", "infos")


def digest(value: object, path: str = "") -> str:
    """SHA-256 of a checkpoint's content, keys holding wall times left out."""
    h = hashlib.sha256()

    def feed(v: object, where: str) -> None:
        if isinstance(v, dict):
            for k in sorted(v, key=str):
                if not any(s in str(k) for s in SKIP):
                    h.update(str(k).encode())
                    feed(v[k], f"{where}/{k}")
        elif isinstance(v, (list, tuple)):
            for i, x in enumerate(v):
                feed(x, f"{where}/{i}")
        elif isinstance(v, torch.Tensor):
            h.update(v.detach().cpu().contiguous().numpy().tobytes())
        else:
            h.update(repr(v).encode())

    feed(value, path)
    return h.hexdigest()[:16]


def normalised(state: dict) -> dict:
    """A checkpoint of format 3 (the curriculum inside the env's assist part, and a second copy
    beside it) in the layout of format 4 (Algorithm 1's state once, under ``a2cf``), so that
    trees on either side of the change compare by content."""
    if state.get("format") != 3:
        return state
    state = dict(state, format=4, env=dict(state["env"]))
    assist = dict(state["env"]["assist"])
    event = assist.pop("curriculum_event")
    state["env"]["assist"] = assist
    state.pop("curriculum", None)
    if event is not None:
        state["a2cf"] = {
            "curriculum": event["curriculum"],
            "iteration": event["iteration"],
            "steps": event["step_in_iteration"],
            "skill_sum": event["skill_sum"],
            "alone_sum": event["alone_sum"],
            "stats": event["stats"],
            "history": event["history"],
        }
    return state


def main(out: str) -> None:
    from a2cf_mb.cli import main as cli

    result = {}
    for name, args in CASES:
        if len(sys.argv) > 2 and name not in sys.argv[2:]:
            continue
        run = Path(out) / name
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = cli(["train", *args, *COMMON, "--out", out, "--run-name", name])
        if code:
            result[name] = f"exit {code}"
            continue
        state = normalised(torch.load(run / "checkpoints" / "last.pt", weights_only=False))
        parts = {k: digest(v) for k, v in state.items() if k not in SKIP}
        env = state.get("env", {})
        parts.update({f"env.{k}": digest(v) for k, v in env.items()})
        result[name] = parts
        print(name, digest(state), file=sys.stderr, flush=True)
    print(json.dumps(result, indent=1, sort_keys=True))


if __name__ == "__main__":
    main(sys.argv[1])
