"""``dance``: track dance clips (paper, "Dancing") with the clip-tracking command of
:mod:`rl.tasks.dance_terms`.

Each episode starts on a frame drawn uniformly along one clip (drawn uniformly among the task's
clips: the built-in choreography by default, user CSV / NPZ clips with ``dance_task(clips)`` or
the run override ``TrainConfig(task_overrides={"commands.sources": [PATH, ...]})``), the robot put on that frame's pose and velocity and onto the
floor (retargeted clips hover or sink a few cm). Rewards are the paper's table: base displacement
``exp(-2500 |dp - dp_cmd|^2)`` 10, base step rotation ``exp(-100 |dq - dq_cmd|^2)`` 5, joints
``exp(-0.25 |q - q_cmd|^2)`` 20, feet slide -1, action rate -0.01, joint acceleration -2.5e-7,
torque -1e-5, less-assist 2. Skill learned: joint tracking error below 0.16 rad (mean absolute
error per joint). Flat ground, randomised friction, payload and CoM, no pushes. Initial assist
bound: the paper's dance row.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from optimal_control.files import atomic_savefig
from rl import rewards, terminations
from rl.curriculum import paper_bound_rows
from rl.tasks import dance_terms as dt
from rl.tasks.components import SinglePhaseConfig
from rl.tasks.config import InitialStateConfig, PushConfig, SkillTarget, TaskConfig
from rl.tasks.stand import STAND_OBSERVATIONS
from rl.tasks.terms import RewardTerm, TerminationTerm


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
        self.command = env.command.clone()  # targets the state after the next step
        self.ref_pos, self.ref_quat = env.command_gen.reference_pose(ahead=1)
        self.rows: list[dict[str, float]] = []
        # per env: its first episode fell, and its joint error at its last step (as training's
        # TrackingSkill charges an episode: the last error if it ran on, fall_error_rad if it fell)
        self.fell = torch.zeros(env.num_envs, dtype=torch.bool)
        self.last_error_rad = torch.zeros(env.num_envs)

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Errors of the envs still in their first episode (not those reset in this step)."""
        s = env.env_state
        done = dones.bool().cpu()
        self.fell |= active & done & ~extras["time_outs"].bool().cpu()
        keep = active & ~done
        all_err = (s.joint_pos_rad - self.command[:, 7:]).abs()
        self.last_error_rad = torch.where(keep, all_err.mean(dim=-1), self.last_error_rad)
        if keep.any():
            err = all_err[keep]
            row = {
                f"joint_{part}_rad": float(err[:, idx].mean())
                for part, idx in dt.BODY_PARTS.items()
            }
            row["joint_all_rad"] = float(err.mean())
            row["base_position_m"] = float((s.base_pos_w - self.ref_pos)[keep].norm(dim=-1).mean())
            row["base_orientation_rad"] = float(
                dt.quat_angle(s.base_quat_w, self.ref_quat)[keep].mean()
            )
            state_cmd = dataclasses.replace(s, command=self.command)
            row["base_displacement_err_m"] = float(
                dt.base_displacement_error_sq(state_cmd)[keep].sqrt().mean()
            )
            row["active_envs"] = int(keep.sum())
            self.rows.append(row)
        self.command = env.command.clone()
        self.ref_pos, self.ref_quat = env.command_gen.reference_pose(ahead=1)

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
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        t = np.arange(len(self.rows)) * self._env.step_dt_s
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
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
        plt.close(fig)


def dance_task(clips: tuple[str | Path, ...] = (dt.BUILTIN_CLIP,)) -> TaskConfig:
    """The dance task tracking ``clips`` (``"builtin"`` and/or CSV / NPZ paths), one per episode."""
    sources = tuple(str(c) for c in clips)
    return dataclasses.replace(
        _DANCE,
        description=f"{_DANCE.description}; clips: {', '.join(sources)}",
        commands=dataclasses.replace(_DANCE.commands, sources=sources),
    )


_DANCE = TaskConfig(
    name="dance",
    description="track dance clips: command [base step displacement, step rotation, joints]",
    observations=STAND_OBSERVATIONS,
    rewards=(
        RewardTerm("base_position", dt.track_base_position, weight=10.0, params={"scale": 2500.0}),
        RewardTerm("base_rotation", dt.track_base_rotation, weight=5.0, params={"scale": 100.0}),
        # broad term: a gradient far from the reference (the paper's, at a quarter of its weight)
        RewardTerm("joint_position", dt.track_joint_position, weight=5.0, params={"scale": 0.25}),
        # steep term around the 0.16 rad target (see docs/environments.md, "dance")
        RewardTerm("joint_rms", dt.track_joint_rms, weight=15.0, params={"std_rad": 0.2}),
        RewardTerm("feet_slide", rewards.feet_slide, weight=-1.0),
        RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.01),
        RewardTerm("joint_acc", rewards.joint_acc_l2, weight=-2.5e-7),
        RewardTerm("torques", rewards.torques_l2, weight=-1e-5),
        # times dt 0.02 s: -2 per fall (the paper's table pays 33/s for a fall in the first step,
        # more than holding a pose earns; tests/test_reward_recipes.py)
        RewardTerm("termination", rewards.termination, weight=-100.0),
    ),
    terminations=(
        TerminationTerm("too_low", terminations.base_too_low, params={"min_height_m": 0.4}),
        TerminationTerm("tilted", terminations.base_tilted, params={"max_tilt_rad": 1.0}),
        TerminationTerm(
            "link_on_ground",
            terminations.link_on_ground,
            params={"bodies": ("pelvis", "torso_link")},
        ),
    ),
    assist_bound=paper_bound_rows("dance"),
    episode_length_s=10.0,
    # The reset puts the robot exactly on its reference frame (the command's reset_state).
    initial_state=InitialStateConfig(joint_pos_noise_rad=0.0, base_vel_noise=0.0, random_yaw=False),
    pushes=PushConfig(enabled=False),
    commands=dt.ClipTrackingConfig(),
    phases=SinglePhaseConfig(names=("dance",)),
    skill=dt.TrackingSkillConfig(threshold_rad=0.16),
    less_assist_weight=2.0,
    evaluation=DanceEvaluationConfig(),
    target=SkillTarget(min_survival=0.0, metric="skill_error_rad", max_metric=0.16),
)

DANCE = dance_task()
"""The registered dance task (built-in choreography), with the steep joint-tracking recipe."""

_PAPER_JOINT = RewardTerm(
    "joint_position", dt.track_joint_position, weight=20.0, params={"scale": 0.25}
)
DANCE_PAPER = dataclasses.replace(
    DANCE,
    name="dance-paper",
    description="the dance with the paper's reward table term for term (joints exp(-0.25|e|^2) x 20)",
    rewards=tuple(
        _PAPER_JOINT if t.name == "joint_position" else t
        for t in DANCE.rewards
        if t.name not in ("joint_rms", "termination")
    ),
)
"""The dance with the paper's reward table (the reference the default recipe is compared with)."""
