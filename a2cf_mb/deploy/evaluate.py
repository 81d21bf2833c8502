"""``a2cf-mb eval BUNDLE_FOLDER``: an exported policy's folder (``policy.json``, ``policy.onnx``,
``reference.npz``) evaluated by the standalone runner (:mod:`a2cf_mb.deploy.run_bundle`), which
rebuilds the training env's G1 from the bundle's facts; a run folder goes to
:func:`rl.evaluation.policy.evaluate`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

RUN_CONFIG_FILE = "config.json"
"""What makes a folder a run folder (``rl.runs.folder.CONFIG_FILE``) rather than a bundle."""


RUN_ONLY_FILES = ("checkpoints", "metrics.jsonl")
"""What only a run folder holds: one of them without ``config.json`` is a run that lost its
config (``eval`` then says to restore it), not a bundle."""


def is_bundle_folder(folder: str | Path) -> bool:
    """``folder`` holds an exported policy's ``policy.json`` and is no run folder."""
    folder = Path(folder)
    run_files = [name for name in (RUN_CONFIG_FILE, *RUN_ONLY_FILES) if (folder / name).exists()]
    return (folder / "policy.json").is_file() and not run_files


def evaluate_bundle(folder: str | Path, cfg: Any) -> dict[str, Any]:
    """Play the bundle in ``folder`` with :func:`a2cf_mb.deploy.run_bundle.run_bundle`:
    ``cfg`` (:class:`rl.evaluation.policy.EvalConfig`) gives the robots, steps and seed; the
    options that need the training code (checkpoint, video, sim2sim, scripted commands) are
    refused with what to do instead."""
    from rl.evaluation.policy import EvalConfig

    default = EvalConfig()
    refused = [
        flag
        for flag, field in (("--no-use-onnx", "use_onnx"), ("--video", "video"),
                            ("--sim2sim", "sim2sim"), ("--scripted", "scripted"))
        if getattr(cfg, field) != getattr(default, field)
    ]  # fmt: skip
    if refused:
        raise ValueError(
            f"{folder} is a policy bundle, not a run folder: {' '.join(refused)} need(s) the run "
            "folder it was exported from (`a2cf-mb eval RUN_DIR`)"
        )
    from a2cf_mb.deploy.run_bundle import run_bundle

    return run_bundle(folder, num_envs=cfg.num_envs, num_steps=cfg.num_steps, seed=cfg.seed)
