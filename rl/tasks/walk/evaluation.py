"""Walk evaluation (``TaskConfig.evaluation`` of ``walk``): per terrain type and level, with
assistance off, survival, linear and yaw velocity-tracking error, distance walked and the level;
per command (stop, forward, backward, sideways, turn; or the segments of a scripted sequence) the
errors beside those a robot standing still would score on the same frames.

:meth:`WalkEvaluationConfig.build` pins env i to a tile (column i mod num_cols, level
``levels[(i // num_cols) mod len(levels)]``) and re-places every robot; each env's first episode
is scored. :meth:`WalkEvaluator.finish` writes ``walk_eval.json`` and ``walk_eval.png`` into the
run folder and returns the table.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from optimal_control.files import atomic_savefig, atomic_write_json
from rl.tasks.walk.command import CommandSegment

EVAL_JSON = "walk_eval.json"
EVAL_PLOT = "walk_eval.png"

COMMAND_KINDS = ("stop", "forward", "backward", "sideways", "turn")
"""Rows of the per-command table of random draws (:func:`command_kind`)."""

JUDGED_KINDS = ("stop", "forward", "backward", "sideways", "turn", "mixed")
"""Rows of the judge per command kind (``WalkEvaluationConfig.judge_kinds``): env i holds a pure
command of kind ``i mod 6`` for its whole episode; ``mixed`` envs draw as in training."""

PURE_KIND_SCALE = 0.8
"""A judged forward, backward or turn command is this share of its range's end [-] (sideways:
the whole end, the range being narrow)."""

DEMO_SCRIPT = (
    CommandSegment("forward", 4.0, (0.8, 0.0, 0.0)),
    CommandSegment("backward", 4.0, (-0.4, 0.0, 0.0)),
    CommandSegment("sideways", 4.0, (0.0, 0.3, 0.0)),
    CommandSegment("turn", 4.0, (0.0, 0.0, 0.8)),
    CommandSegment("stop", 4.0, (0.0, 0.0, 0.0)),
)
"""The scripted sequence of a walk video (``walk_script``): each pure command kind for 4 s, one
20 s episode."""


def command_kind(command: torch.Tensor) -> torch.Tensor:
    """(N,) index into :data:`COMMAND_KINDS` of commands (N, >= 3): stop below 0.1 m/s and
    0.1 rad/s; else the largest of |vx| / 1 m/s, |vy| / 0.3 m/s, |yaw rate| / 1 rad/s."""
    vx, vy, wz = command[:, 0], command[:, 1], command[:, 2]
    share = torch.stack([vx.abs(), vy.abs() / 0.3, wz.abs()], dim=-1)
    dominant = share.argmax(dim=-1)
    kind = torch.where(dominant == 0, torch.where(vx >= 0, 1, 2), dominant + 2)
    stop = (command[:, :2].norm(dim=-1) < 0.1) & (wz.abs() < 0.1)
    return torch.where(stop, 0, kind)


def judged_commands(cfg: Any, num_envs: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Each env's judged kind (N,) (index into :data:`JUDGED_KINDS`, env i of kind i mod 6) and
    its held command (N, 3) from the command ranges of ``cfg`` (a ``VelocityCommandConfig``):
    forward and backward at :data:`PURE_KIND_SCALE` of the vx range's ends, sideways at the vy
    range's end, turning at that share of the yaw-rate range's end; sideways and turning change
    side every other block of six envs. ``mixed`` rows are zeros (they are not held)."""
    i = torch.arange(num_envs)
    kind = i % len(JUDGED_KINDS)
    side = torch.where((i // len(JUDGED_KINDS)) % 2 == 0, 1.0, -1.0)
    vx_low, vx_high = cfg.lin_vel_x_range_mps
    vy_end = max(abs(v) for v in cfg.lin_vel_y_range_mps)
    wz_end = max(abs(v) for v in cfg.ang_vel_z_range_rps)
    per_kind = torch.tensor(
        [
            [0.0, 0.0, 0.0],  # stop
            [PURE_KIND_SCALE * vx_high, 0.0, 0.0],  # forward
            [PURE_KIND_SCALE * vx_low, 0.0, 0.0],  # backward
            [0.0, vy_end, 0.0],  # sideways (x side)
            [0.0, 0.0, PURE_KIND_SCALE * wz_end],  # turn on the spot (x side)
            [0.0, 0.0, 0.0],  # mixed: drawn
        ]
    )
    commands = per_kind[kind]
    commands[:, 1:] *= side[:, None]
    return kind, commands


def command_score(per_command: list[dict[str, Any]]) -> float:
    """The worst kind's error over its bar (<= 1: every kind tracked; :data:`JUDGED_KINDS`):
    forward, backward and sideways by the velocity error against half a robot standing still's
    on the same steps, turning by the yaw-rate error likewise, mixed by both; stop, where
    standing still scores 0, by each error against the smallest bar of its unit among the moving
    kinds (a policy that steps in place under "stop" must stay within that)."""
    rows = {r["command"]: r for r in per_command}
    lin, yaw = "lin_vel_error_mps", "yaw_rate_error_rps"
    keys = {"forward": (lin,), "backward": (lin,), "sideways": (lin,), "turn": (yaw,),
            "mixed": (lin, yaw)}  # fmt: skip
    ratios = []
    bars: dict[str, list[float]] = {lin: [], yaw: []}
    for name, judged in keys.items():
        if name not in rows:
            continue
        for key in judged:
            bar = 0.5 * rows[name][f"standing_still_{key}"]
            if bar > 1e-6:  # steps that asked for nothing of this kind are judged by stop's bar
                bars[key].append(bar)
                ratios.append(rows[name][key] / bar)
    if "stop" in rows:
        ratios += [rows["stop"][key] / min(b) for key, b in bars.items() if b]
    return float(max(ratios, default=float("inf")))


@dataclass(frozen=True)
class WalkEvaluationConfig:
    """Which terrain levels the walk evaluation places robots on, and an optional scripted
    command sequence in place of the env's random draws."""

    in_sim2sim: ClassVar[bool] = True
    """Its evaluator reads only what the sim2sim robots have (:mod:`rl.evaluation.sim2sim` scores
    their rollouts with it too, all on flat ground: one "flat" row at level 0)."""
    levels: tuple[int, ...] = (0, 3, 6, 9)
    """terrain levels to test, cycled over env blocks [-]"""
    command_script: tuple[CommandSegment, ...] = ()
    """every env follows these segments (e.g. DEMO_SCRIPT); empty: the env's random draws"""
    judge_kinds: bool = False
    """env i holds a pure command of kind ``JUDGED_KINDS[i mod 6]``, and ``command_score`` judges
    each kind against a robot standing still (:func:`command_score`); a script overrides it"""

    def scripted(self) -> WalkEvaluationConfig:
        """This config with :data:`DEMO_SCRIPT` as every env's commands (``eval --scripted``)."""
        return dataclasses.replace(self, command_script=DEMO_SCRIPT)

    def build(self, env: Any) -> WalkEvaluator:
        """Pin the env's robots to evaluation tiles, re-place them, and return the evaluator."""
        return WalkEvaluator(self, env)


class WalkEvaluator:
    """Accumulates per-env tracking errors and distance over each env's first episode."""

    def __init__(self, cfg: WalkEvaluationConfig, env: Any) -> None:
        n = env.num_envs
        curriculum = env.skill
        self.curriculum = curriculum if hasattr(curriculum, "pin_tiles") else None
        if self.curriculum is not None:  # rough terrain: pin the robots to the levels tested
            terrain = curriculum.terrain
            rows = terrain.num_rows
            bad = [lv for lv in cfg.levels if not 0 <= lv < rows]
            if bad or not cfg.levels:
                raise ValueError(f"walk evaluation levels {bad or '()'} outside [0, {rows - 1}]")
            cols = terrain.num_cols
            i = torch.arange(n)
            levels = torch.tensor(cfg.levels)[(i // cols) % len(cfg.levels)]
            self.tiles = torch.stack([levels, i % cols], dim=-1)
            curriculum.pin_tiles(self.tiles)
            self.types = [terrain.tile_type(int(c)) for c in self.tiles[:, 1]]
        else:  # flat ground: one "flat" row at level 0
            self.tiles = torch.zeros(n, 2, dtype=torch.long)
            self.types = ["flat"] * n
        self.script = cfg.command_script
        self.env_kind: torch.Tensor | None = None  # (N,) index into JUDGED_KINDS
        if self.script:
            env.command_gen.follow_script(self.script)
            self.kinds = tuple(seg.name for seg in self.script)
        elif cfg.judge_kinds:
            kind, commands = judged_commands(env.command_gen.cfg, n)
            env.command_gen.hold(kind != JUDGED_KINDS.index("mixed"), commands)
            self.env_kind = kind.to(env.command_gen.device)  # read every step, on the env's device
            self.kinds = JUDGED_KINDS
        else:
            self.kinds = COMMAND_KINDS
        k = len(self.kinds)
        # per command kind: lin. error, yaw error, standing still's two errors [m/s, rad/s], steps
        self.kind_sums = torch.zeros(k, 5)
        env.reset_envs(torch.arange(n, device=env.device))
        self.start_xy_w = env.env_state.base_pos_w[:, :2].cpu().clone()
        self.lin_error_sum = torch.zeros(n)
        self.yaw_error_sum = torch.zeros(n)
        self.still_error_sums = torch.zeros(n, 2)  # a robot standing still: |v_cmd|, |w_cmd|
        self.steps = torch.zeros(n)
        self.distance_m = torch.zeros(n)
        self.fell = torch.zeros(n, dtype=torch.bool)

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Add this step's errors for envs still in their first episode (``active`` before it)."""
        s = env.env_state  # on the env's device: this step's figures are computed there
        lin = (s.base_lin_vel_b[:, :2] - s.command[:, :2]).norm(dim=-1)
        yaw = (s.base_ang_vel_b[:, 2] - s.command[:, 2]).abs()
        if self.env_kind is not None:
            kind = self.env_kind
        elif self.script:
            kind = env.command_gen.segment()
        else:
            kind = command_kind(s.command)
        # this evaluator's buffers are on the host: only the (N, 7) figures cross, in one copy
        figures = torch.stack(
            [lin, yaw, s.command[:, :2].norm(dim=-1), s.command[:, 2].abs(), kind.float(),
             s.base_pos_w[:, 0], s.base_pos_w[:, 1]], dim=-1,
        ).cpu()  # fmt: skip
        lin, yaw, xy_w = figures[:, 0], figures[:, 1], figures[:, 5:]
        done = dones.bool().cpu()
        alive = active & ~done  # the state of done envs is already their next episode's
        self.lin_error_sum += torch.where(alive, lin, 0.0)
        self.yaw_error_sum += torch.where(alive, yaw, 0.0)
        self.steps += alive.float()
        self.still_error_sums += figures[:, 2:4] * alive[:, None]
        row = torch.cat([figures[:, :4], torch.ones(len(lin), 1)], dim=-1) * alive[:, None]
        self.kind_sums.index_add_(0, figures[:, 4].long(), row)
        dist = (xy_w - self.start_xy_w).norm(dim=-1)
        self.distance_m = torch.where(alive, dist, self.distance_m)
        self.fell |= active & done & ~extras["time_outs"].bool().cpu()

    def table(self) -> list[dict[str, Any]]:
        """One row per (terrain type, level) with the mean figures of its envs."""
        rows = []
        steps = self.steps.clamp_min(1)
        lin, yaw = self.lin_error_sum / steps, self.yaw_error_sum / steps
        keys = sorted({(t, int(lv)) for t, lv in zip(self.types, self.tiles[:, 0], strict=True)})
        for kind, level in keys:
            mask = torch.tensor(
                [
                    t == kind and int(lv) == level
                    for t, lv in zip(self.types, self.tiles[:, 0], strict=True)
                ]
            )
            rows.append(
                {
                    "terrain": kind,
                    "level": level,
                    "envs": int(mask.sum()),
                    "survival": float((~self.fell[mask]).float().mean()),
                    "lin_vel_error_mps": float(lin[mask].mean()),
                    "yaw_rate_error_rps": float(yaw[mask].mean()),
                    "distance_m": float(self.distance_m[mask].mean()),
                }
            )
        return rows

    def per_command(self) -> list[dict[str, Any]]:
        """One row per command kind (or script segment) that some live step had: the mean
        errors, and those of a robot standing still (|v_cmd|, |yaw rate_cmd|) on the same steps."""
        rows = []
        for name, sums in zip(self.kinds, self.kind_sums, strict=True):
            steps = float(sums[4])
            if steps == 0:
                continue
            rows.append(
                {
                    "command": name,
                    "steps": int(steps),
                    "lin_vel_error_mps": float(sums[0]) / steps,
                    "yaw_rate_error_rps": float(sums[1]) / steps,
                    "standing_still_lin_vel_error_mps": float(sums[2]) / steps,
                    "standing_still_yaw_rate_error_rps": float(sums[3]) / steps,
                }
            )
        return rows

    def finish(self, run_dir: str | Path) -> dict[str, Any]:
        """Write ``walk_eval.json`` and ``walk_eval.png`` into ``run_dir``; return the figures."""
        table = self.table()
        steps = self.steps.clamp_min(1)
        still = self.still_error_sums / steps[:, None]
        result = {
            "survival": float((~self.fell).float().mean()),
            "lin_vel_error_mps": float((self.lin_error_sum / steps).mean()),
            "yaw_rate_error_rps": float((self.yaw_error_sum / steps).mean()),
            "distance_m": float(self.distance_m.mean()),
            "mean_level": float(self.tiles[:, 0].float().mean()),
            # the same figures for a robot standing still on the same frames (the bar to beat)
            "standing_still_lin_vel_error_mps": float(still[:, 0].mean()),
            "standing_still_yaw_rate_error_rps": float(still[:, 1].mean()),
            "command_script": [seg.name for seg in self.script],
            "per_command": self.per_command(),
            "per_terrain_level": table,
        }
        if self.env_kind is not None:
            result["command_score"] = command_score(result["per_command"])
        run_dir = Path(run_dir)
        atomic_write_json(run_dir / EVAL_JSON, result)
        _plot(table, result["per_command"], result["survival"], run_dir / EVAL_PLOT)
        result["plot"] = str(run_dir / EVAL_PLOT)
        return result


def _plot(
    table: list[dict[str, Any]], per_command: list[dict[str, Any]], survival: float, path: Path
) -> None:
    """Velocity and yaw-rate errors per command beside a robot standing still's on the same steps
    (the bar a walker must beat), and, where the evaluation spans terrain levels, survival,
    tracking errors and distance per terrain type against level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = (
        ("survival", "survival [-]"),
        ("lin_vel_error_mps", "lin. vel. error [m/s]"),
        ("yaw_rate_error_rps", "yaw-rate error [rad/s]"),
        ("distance_m", "distance [m]"),
    )
    errors = (
        ("lin_vel_error_mps", "lin. vel. error [m/s]"),
        ("yaw_rate_error_rps", "yaw-rate error [rad/s]"),
    )
    # one level (flat): its row is the overall figures, so the panels per command say more
    by_level = len(table) > 1 or not per_command
    panels = (len(metrics) if by_level else 0) + (len(errors) if per_command else 0)
    fig, axes = plt.subplots(1, max(panels, 1), figsize=(4 * max(panels, 1), 3.6), squeeze=False)
    axes = list(axes[0])
    if by_level:
        level_axes, axes = axes[: len(metrics)], axes[len(metrics) :]
        for kind in sorted({r["terrain"] for r in table}):
            rows = sorted((r for r in table if r["terrain"] == kind), key=lambda r: r["level"])
            for ax, (key, _) in zip(level_axes, metrics, strict=True):
                ax.plot([r["level"] for r in rows], [r[key] for r in rows], "o-", label=kind)
        for ax, (_, label) in zip(level_axes, metrics, strict=True):
            ax.set_xlabel("terrain level")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        level_axes[0].legend(fontsize=7)
    if per_command:
        names = [r["command"] for r in per_command]
        x = np.arange(len(names))
        for ax, (key, label) in zip(axes, errors, strict=True):
            ax.bar(x - 0.2, [r[key] for r in per_command], 0.4, label="policy")
            ax.bar(x + 0.2, [r[f"standing_still_{key}"] for r in per_command], 0.4,
                   color="0.7", label="standing still")  # fmt: skip
            ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3, axis="y")
        axes[0].legend(fontsize=7)
    fig.suptitle(f"walk evaluation, assistance off: survival {survival:.0%}")
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=100)
    plt.close(fig)
