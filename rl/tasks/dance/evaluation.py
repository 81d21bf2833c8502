"""``a2cf-mb eval`` of the dance: tracking errors per body part, pelvis position and orientation
against the reference, the training skill measure's episode error, and a plot over time."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from optimal_control.files import atomic_savefig
from rl.envs.state import quat_multiply
from rl.tasks.dance.terms import base_displacement_error_sq
from robots import g1


def quat_angle(a_wxyz: torch.Tensor, b_wxyz: torch.Tensor) -> torch.Tensor:
    """Rotation angle between orientations (N, 4) w x y z, shape (N,) [rad]."""
    conj = b_wxyz * torch.tensor([1.0, -1.0, -1.0, -1.0])
    rel = quat_multiply(conj, a_wxyz)
    return 2 * torch.atan2(rel[:, 1:].norm(dim=-1), rel[:, 0].abs())


@dataclass(frozen=True)
class DanceEvaluationConfig:
    """``a2cf-mb eval`` metrics of the dance: tracking errors per body part, base position and
    orientation against the reference, and a plot over time."""

    plot_name: str = "eval_dance.png"  # figure written into the run folder [-]

    def build(self, env: Any) -> DanceEvaluator:
        """The evaluator of one eval rollout on ``env`` (a dance :class:`G1VecEnv`)."""
        return DanceEvaluator(self, env)


class DanceEvaluator:
    """Per step of each env's first episode: joint errors per body part [rad], pelvis position
    error [m] and orientation error [rad] against the reference frame it should be on."""

    def __init__(self, cfg: DanceEvaluationConfig, env: Any) -> None:
        self.cfg = cfg
        self._env = env
        self._read_reference(env)  # targets the state after the next step
        self.rows: list[dict[str, float]] = []
        # per env: its first episode fell, and its joint error at its last step (as training's
        # TrackingSkill charges an episode: the last error if it ran on, fall_error_rad if it fell)
        self.fell = torch.zeros(env.num_envs, dtype=torch.bool)
        self.last_error_rad = torch.zeros(env.num_envs)

    def _read_reference(self, env: Any) -> None:
        """The command and reference pose the state after the next step is judged by (host)."""
        self.command = env.command.cpu().clone()
        self.ref_pos, self.ref_quat = (t.cpu() for t in env.command_gen.reference_pose(ahead=1))

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Errors of the envs still in their first episode (not those reset in this step)."""
        s = env.env_state.to("cpu")  # this evaluator's buffers are on the host
        done = dones.bool().cpu()
        self.fell |= active & done & ~extras["time_outs"].bool().cpu()
        keep = active & ~done
        all_err = (s.joint_pos_rad - self.command[:, 7:]).abs()
        self.last_error_rad = torch.where(keep, all_err.mean(dim=-1), self.last_error_rad)
        if keep.any():
            err = all_err[keep]
            row = {
                f"joint_{part}_rad": float(err[:, idx].mean())
                for part, idx in g1.BODY_PARTS.items()
            }
            row["joint_all_rad"] = float(err.mean())
            # what holding the default pose would score on the same frames: a joint error above
            # it is no tracking at all (the built-in dance's is about 0.07 rad)
            standing = (s.default_joint_pos_rad - self.command[:, 7:]).abs()[keep]
            row["joint_all_standing_rad"] = float(standing.mean())
            row["base_position_m"] = float((s.base_pos_w - self.ref_pos)[keep].norm(dim=-1).mean())
            row["base_orientation_rad"] = float(
                quat_angle(s.base_quat_w, self.ref_quat)[keep].mean()
            )
            state_cmd = dataclasses.replace(s, command=self.command)
            row["base_displacement_err_m"] = float(
                base_displacement_error_sq(state_cmd)[keep].sqrt().mean()
            )
            row["active_envs"] = int(keep.sum())
            self.rows.append(row)
        self._read_reference(env)

    def finish(self, run_dir: str | Path) -> dict[str, Any]:
        """Step-weighted means of every error (and the figure in ``run_dir``)."""
        if not self.rows:
            return {"steps": 0}
        weight = torch.tensor([r["active_envs"] for r in self.rows], dtype=torch.float64)
        keys = [k for k in self.rows[0] if k != "active_envs"]
        out: dict[str, Any] = {
            k: float((torch.tensor([r[k] for r in self.rows]) * weight).sum() / weight.sum())
            for k in keys
        }
        skill = self._env.task.skill
        out["skill_threshold_rad"] = skill.threshold_rad
        # the training measure's per-episode error: a fall costs fall_error_rad, so a policy
        # that tracks well until it falls has not learned the dance
        episode_err = torch.where(self.fell, skill.fall_error_rad, self.last_error_rad)
        out["skill_error_rad"] = float(episode_err.mean())
        out["fell_fraction"] = float(self.fell.float().mean())
        out["skill_learned"] = out["skill_error_rad"] < skill.threshold_rad
        out["steps"] = len(self.rows)
        plot = Path(run_dir) / self.cfg.plot_name
        self._plot(plot, keys)
        out["plot"] = str(plot)
        return out

    def _plot(self, path: Path, keys: list[str]) -> None:
        import numpy as np
        from matplotlib.figure import Figure  # no pyplot: a notebook's backend stays as it is

        t = np.arange(len(self.rows)) * self._env.step_dt_s
        fig = Figure(figsize=(10, 3.5))
        axes = fig.subplots(1, 2)
        for k in keys:
            if k.startswith("joint_"):
                axes[0].plot(t, [r[k] for r in self.rows], label=k[6:-4])
        axes[0].axhline(self._env.task.skill.threshold_rad, color="k", ls="--", lw=0.8)
        axes[0].set_ylabel("mean |q - q_ref| [rad]")
        axes[0].legend(fontsize=7)
        axes[1].plot(t, [r["base_position_m"] for r in self.rows], label="pelvis position [m]")
        axes[1].plot(
            t, [r["base_orientation_rad"] for r in self.rows], label="pelvis orientation [rad]"
        )
        axes[1].legend(fontsize=7)
        for ax in axes:
            ax.set_xlabel("time [s]")
        fig.tight_layout()
        atomic_savefig(fig, path, dpi=100)
