"""``a2cf-mb eval`` of a tracking task, and its skill measure that standing still cannot pass.

Each evaluation env tracks one reference from its first frame (env ``i``: reference ``i mod K``)
to its last (or the episode's cap). An episode *succeeds* when it neither falls nor drifts past
the termination thresholds (both end it). On the frames each env tracked, the evaluator scores
the robot and, beside it, a *statue*: the robot holding its standing pose where the episode
started (joints at the standing pose, pelvis and links where they were at the first frame).

The skill counts as tracked when the mean joint error is below ``max_joint_error_rad`` (the
paper's 0.16 rad) **and** at most ``max_statue_ratio`` (0.5) of the statue's on the same frames:
``tracking_score = max(joint / 0.16, (joint / statue) / 0.5)`` <= 1. On a reference that barely
moves the statue's error is small, and only real tracking beats half of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import torch

from optimal_control.files import atomic_savefig
from rl.tasks.track.terms import ANCHOR, TRACKED_BODIES, quat_angle
from robots import g1

PELVIS = TRACKED_BODIES.index("pelvis")


@dataclass(frozen=True)
class TrackEvaluationConfig:
    """The tracking evaluation: its thresholds and figure."""

    in_sim2sim: ClassVar[bool] = True
    """Its evaluator reads only what the sim2sim robots have (:class:`rl.evaluation.sim2sim`
    scores their rollouts with it too)."""
    max_joint_error_rad: float = 0.16  # mean |q - q_ref| that counts as tracked (paper) [rad]
    max_statue_ratio: float = 0.5  # joint error at most this share of the statue's [-]
    plot_name: str = "eval_track.png"  # figure written into the run folder [-]

    def build(self, env: Any) -> TrackEvaluator:
        """The evaluator of one rollout on ``env`` (a tracking task's :class:`G1VecEnv`)."""
        return TrackEvaluator(self, env)


_METRICS = ("joint", "legs", "waist", "arms", "pelvis_pos", "pelvis_rot", "body_pos", "body_rel")


class TrackEvaluator:
    """Per env, sums over the frames of its first episode of the robot's and the statue's errors
    (joints by body part [rad], pelvis position [m] and orientation [rad], tracked links'
    positions in the world (MPKPE) and relative to the anchor [m]); and the per-step curve."""

    def __init__(self, cfg: TrackEvaluationConfig, env: Any) -> None:
        self.cfg = cfg
        self._env = env
        n = env.num_envs
        self.sums = {k: torch.zeros(n, dtype=torch.float64) for k in _METRICS}
        self.statue = {k: torch.zeros(n, dtype=torch.float64) for k in _METRICS}
        self.frames = torch.zeros(n, dtype=torch.float64)
        self.fell = torch.zeros(n, dtype=torch.bool)
        self.curve: list[tuple[float, float, int]] = []  # (robot, statue joint error, envs)
        s = env.env_state.to("cpu")
        self._statue_pos = s.body_pos_w.clone()  # the links where each episode started
        self._statue_quat = s.body_quat_w.clone()
        self._read_targets(env)

    def _read_targets(self, env: Any) -> None:
        """The targets the state after the next step is judged by (host copies)."""
        self._targets = {k: v.cpu().clone() for k, v in env.task_components.targets.items()}

    def _errors(self, pos, quat, joints, t) -> dict[str, torch.Tensor]:
        jerr = (joints - t["joint_pos_rad"]).abs()
        ref_anchor = t["body_pos_w"][:, ANCHOR : ANCHOR + 1]
        rel_ref = t["body_pos_w"] - ref_anchor
        rel = pos - pos[:, ANCHOR : ANCHOR + 1]
        out = {"joint": jerr.mean(-1)}
        for part, idx in g1.BODY_PARTS.items():
            out[part] = jerr[:, idx].mean(-1)
        out["pelvis_pos"] = (pos[:, PELVIS] - t["body_pos_w"][:, PELVIS]).norm(dim=-1)
        out["pelvis_rot"] = quat_angle(quat[:, PELVIS], t["body_quat_w"][:, PELVIS])
        out["body_pos"] = (pos - t["body_pos_w"]).norm(dim=-1).mean(-1)
        out["body_rel"] = (rel - rel_ref).norm(dim=-1).mean(-1)
        return out

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Errors of the envs still in their first episode (including the step that ends it by a
        time-out at the reference's end; not one that ends it by a fall)."""
        s = env.env_state.to("cpu")
        done = dones.bool().cpu()
        time_out = extras["time_outs"].bool().cpu()
        fell_now = active & done & ~time_out
        self.fell |= fell_now
        keep = active & ~fell_now
        if keep.any():
            # a reset env's state is its new episode's: score the ones that were not reset only
            keep &= ~done
            t = self._targets
            robot = self._errors(s.body_pos_w, s.body_quat_w, s.joint_pos_rad, t)
            stand = s.default_joint_pos_rad.expand_as(s.joint_pos_rad)
            statue = self._errors(self._statue_pos, self._statue_quat, stand, t)
            w = keep.double()
            for k in _METRICS:
                self.sums[k] += robot[k].double() * w
                self.statue[k] += statue[k].double() * w
            self.frames += w
            if keep.any():
                self.curve.append(
                    (float(robot["joint"][keep].mean()), float(statue["joint"][keep].mean()),
                     int(keep.sum()))
                )  # fmt: skip
        self._read_targets(env)

    def finish(self, run_dir: str | Path) -> dict[str, Any]:
        """Frame-weighted errors of robot and statue, success, the tracking score, per reference."""
        names = self._env.command_gen.library.names
        clip = torch.arange(self._env.num_envs) % len(names)
        out = self._summary(torch.ones_like(self.fell))
        out["per_reference"] = {name: self._summary(clip == k) for k, name in enumerate(names)}
        plot = Path(run_dir) / self.cfg.plot_name
        self._plot(plot)
        out["plot"] = str(plot)
        return out

    def _summary(self, envs: torch.Tensor) -> dict[str, Any]:
        frames = float(self.frames[envs].sum())
        if frames == 0:
            return {"steps": 0, "success_rate": 0.0, "tracking_score": float("inf")}
        out: dict[str, Any] = {}
        for k in _METRICS:
            unit = "m" if k in ("pelvis_pos", "body_pos", "body_rel") else "rad"
            out[f"{k}_error_{unit}"] = float(self.sums[k][envs].sum()) / frames
            out[f"statue_{k}_error_{unit}"] = float(self.statue[k][envs].sum()) / frames
        joint, statue = out["joint_error_rad"], out["statue_joint_error_rad"]
        out["statue_ratio"] = joint / max(statue, 1e-9)
        out["tracking_score"] = max(
            joint / self.cfg.max_joint_error_rad, out["statue_ratio"] / self.cfg.max_statue_ratio
        )
        out["success_rate"] = float((~self.fell[envs]).float().mean())
        out["tracked"] = out["tracking_score"] <= 1.0
        out["frames_scored"] = int(frames)
        return out

    def _plot(self, path: Path) -> None:
        import numpy as np
        from matplotlib.figure import Figure  # no pyplot: a notebook's backend stays as it is

        fig = Figure(figsize=(7, 3.2))
        ax = fig.subplots()
        if self.curve:
            t = np.arange(len(self.curve)) * self._env.step_dt_s
            ax.plot(t, [c[0] for c in self.curve], label="policy alone")
            ax.plot(t, [c[1] for c in self.curve], label="statue (standing pose)", ls=":")
        ax.axhline(self.cfg.max_joint_error_rad, color="k", ls="--", lw=0.8, label="0.16 rad")
        ax.set_xlabel("time along the reference [s]")
        ax.set_ylabel("mean |q - q_ref| [rad]")
        ax.legend(fontsize=7)
        fig.tight_layout()
        atomic_savefig(fig, path, dpi=100)
