"""``train --oracle``: the tracked clip's oracle artifact, solved once per segment and cached.

The artifact is ``solve-dance --clip FILE --clip-frames A:B``'s (the per-frame wrench QP along
the clip, :func:`optimal_control.oracle.solve_dance`), with eta0 per time bin of the tracking
command's adaptive-sampling bins (``--phase-bin-s``, 1 s). It is written to
``<out>/oracle_cache/<fingerprint>/``, ``<fingerprint>`` being the reference's as the task tracks it
(:func:`optimal_control.reference_sources.reference_fingerprint`: the segment's motion at the
policy rate), and reused by every later run on the same motion. The run's ``oracle_artifact``
records the folder; through it:

* ``--task-action-feedforward`` puts the artifact's joint torques (alpha 1: with the least pelvis
  wrench where the clip is not doable unaided) and the reference's joint rates into the PD law;
* ``--mode a2cf`` starts its curriculum from the artifact's eta0, one bound per time bin (the
  bins are the task's phases), and ``--warmstart oracle`` distils the artifact's coach into the
  force head first;
* ``--mode coach --coach-source oracle`` makes the artifact's coach the help (ZEST).
"""

from __future__ import annotations

import dataclasses
import fcntl
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rl.training.config import TrainConfig

ORACLE_KEYWORD = "oracle"
"""``--warmstart oracle`` / ``--coach-source oracle``: the run's oracle artifact."""

CACHE_DIR = "oracle_cache"
"""Folder under ``TrainConfig.out`` that holds the solved artifacts, one per fingerprint."""


def oracle_cache(out: str | Path) -> Path:
    """The cache folder of the runs under ``out``."""
    return Path(out) / CACHE_DIR


def resolve_oracle(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with its oracle artifact found or solved (``--oracle``) and the ``oracle`` keyword
    of ``--warmstart`` / ``--coach-source`` replaced by its folder; ``cfg`` itself when the run
    asks for no oracle.

    Raises:
        ValueError: the keyword without ``--oracle``; ``--oracle`` on a task or reference it does
            not apply to (one line each, saying what to give).
    """
    keyword = ORACLE_KEYWORD in (cfg.warmstart, cfg.coach.source)
    if not cfg.oracle and not cfg.oracle_artifact:
        if keyword:
            raise ValueError(
                "--warmstart oracle / --coach-source oracle use the run's oracle artifact: add "
                "--oracle (train --task track --reference CLIP --oracle)"
            )
        return cfg
    from optimal_control.artifact import SUMMARY_FILE

    artifact = cfg.oracle_artifact
    if not artifact or not (Path(artifact) / SUMMARY_FILE).is_file():
        if not cfg.oracle:
            raise ValueError(
                f"--oracle-artifact '{artifact}' is not an oracle artifact folder (no "
                f"{SUMMARY_FILE}); give the folder solve-dance --clip wrote, or --oracle"
            )
        artifact = str(cached_oracle(cfg).resolve())
    coach = cfg.coach
    if coach.source == ORACLE_KEYWORD:
        coach = dataclasses.replace(coach, source=artifact)
    warmstart = artifact if cfg.warmstart == ORACLE_KEYWORD else cfg.warmstart
    return dataclasses.replace(cfg, oracle_artifact=artifact, coach=coach, warmstart=warmstart)


def cached_oracle(cfg: TrainConfig) -> Path:
    """The folder of the oracle artifact of ``cfg``'s one tracked clip (and segment): found in
    :func:`oracle_cache` by the reference's fingerprint, or solved there now (one process at a
    time per fingerprint; the others wait and reuse it)."""
    from optimal_control.artifact import SUMMARY_FILE
    from optimal_control.oracle import OracleConfig, solve_dance
    from optimal_control.reference_sources import parse_frames, reference_fingerprint
    from rl.tasks.registry import get_task, with_references
    from rl.tasks.track.command import MotionCommandConfig
    from rl.tasks.track.library import load_track_reference

    task = get_task(cfg.task).with_overrides(cfg.task_overrides)
    cmd = task.commands
    if not isinstance(cmd, MotionCommandConfig):
        raise ValueError(
            f"--oracle solves the oracle of a tracked clip; task '{cfg.task}' tracks none: use "
            "--task track --reference CLIP"
        )
    cmd = with_references(task, cfg.reference, cfg.reference_frames).commands
    if len(cmd.sources) != 1 or not Path(cmd.sources[0]).is_file():
        raise ValueError(
            f"--oracle solves the oracle of one clip file (.csv / .npz); the run tracks "
            f"{', '.join(cmd.sources)}: give one --reference CLIP (an artifact folder already is "
            "an oracle: pass it as --reference, or as --warmstart / --coach-source)"
        )
    source = cmd.sources[0]
    ref = load_track_reference(source, parse_frames(cmd.frames), cmd.step_dt_s)
    fingerprint = reference_fingerprint(ref)
    folder = oracle_cache(cfg.out) / fingerprint
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f"{fingerprint}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # a second run on the segment waits, then reuses
        if not (folder / SUMMARY_FILE).is_file():
            print(f"a2cf-mb train: solving the oracle of {source} into {folder} (once)")
            oracle_cfg = OracleConfig(
                phase_bin_s=cmd.bin_s, video=False, progress=False, out=str(folder)
            )
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the plausibility report is in the summary
                art, _ = solve_dance(cfg=oracle_cfg, clip=source, clip_frames=cmd.frames)
            solved = art.extra_summary["source"]["fingerprint"]
            if solved != fingerprint:
                raise ValueError(
                    f"the oracle of {source} was solved on another motion (fingerprint {solved}) "
                    f"than the task tracks ({fingerprint}); check the clip's ClipConfig"
                )
    return folder
