"""``backflip``: a standing backflip of the G1 through the five-phase FSM of the paper.

Stand -> Crouch -> Jump -> Air -> Land (:mod:`rl.tasks.backflip.terms`), started by the command
``c_t = 1_start`` after a random standing delay. Rewards are the paper's backflip table, each
term masked to its phases; the desired joint pose per phase comes from a backflip oracle artifact
(``backflip_task(artifact_path)``, or the run override ``task_overrides={"term_params":
{"pose_deviation": {"source": PATH}}}``) or from
built-in poses (the default; the task description and ``config.json`` say which). Success =
reaching Land and staying there upright and still for 1 s (to the episode's time-out); the success
rate is the skill measure. A failed flip that lands on hands, knees or back (any non-foot link on
the ground) fails the episode. Flat ground, randomised friction and payload, no pushes; the
heading is fixed (the flip axis is world y, which the balance term in Jump/Air reads). Initial
assist bounds: the paper's per-phase backflip rows.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from optimal_control.files import atomic_savefig
from rl.envs.assist import paper_bound_rows
from rl.envs.task_schema import InitialStateConfig, PushConfig, RandomizationConfig, TaskConfig
from rl.envs.terms import RewardTerm, TerminationTerm
from rl.tasks import rewards, terminations
from rl.tasks.backflip import terms as bt
from rl.tasks.stand.task import PROPRIOCEPTIVE_OBSERVATIONS

GROUND = (bt.STAND, bt.CROUCH, bt.LAND)
FLIGHT = (bt.JUMP, bt.AIR)


@dataclass(frozen=True)
class BackflipEvaluationConfig:
    """``a2cf-mb eval`` metrics of the backflip: success rate, highest phase reached, a plot."""

    plot_name: str = "eval_backflip.png"  # figure written into the run folder [-]

    def build(self, env: Any) -> BackflipEvaluator:
        """The evaluator of one eval rollout on ``env`` (a backflip :class:`G1VecEnv`)."""
        return BackflipEvaluator(self, env)


class BackflipEvaluator:
    """Scores each env's first episode from the FSM's and the skill measure's episode records."""

    def __init__(self, cfg: BackflipEvaluationConfig, env: Any) -> None:
        self.cfg = cfg
        self.names = env.phase_names
        n = env.num_envs
        self.done = torch.zeros(n, dtype=torch.bool)
        self.success = torch.zeros(n, dtype=torch.bool)
        self.max_phase = torch.zeros(n, dtype=torch.long)
        self.turned_rad = torch.zeros(n)
        self.landed_short = torch.zeros(n, dtype=torch.bool)
        self.occupancy: list[list[float]] = []  # per step: fraction of first episodes per phase
        self._env = env

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Record the first episodes that ended in this step and the phase occupancy."""
        fsm, skill = env.phase_machine, env.skill
        ended = active & dones.bool().cpu()
        if ended.any():
            ids = ended.nonzero().flatten()
            self.max_phase[ids] = fsm.last_max_phase[ids]
            self.turned_rad[ids] = fsm.last_turned_rad[ids]
            self.landed_short[ids] = fsm.last_landed_short[ids]
            success = torch.zeros(env.num_envs, dtype=torch.bool)
            success[skill.last_env_ids] = skill.last_success
            self.success[ids] = success[ids]
            self.done[ids] = True
        still = active & ~ended
        phase = fsm.phase
        if still.any():
            self.occupancy.append(
                [float(((phase == p) & still).sum()) / env.num_envs for p in range(len(self.names))]
            )

    def finish(self, run_dir: str | Path) -> dict[str, Any]:
        """Metrics (and the figure in ``run_dir``) over the first episodes."""
        fsm = self._env.phase_machine
        open_ = ~self.done
        self.max_phase[open_] = fsm.max_phase[open_]
        self.turned_rad[open_] = fsm.turned_rad[open_]
        self.landed_short[open_] = fsm.landed_short[open_]
        reached = {
            name: float((self.max_phase >= p).float().mean()) for p, name in enumerate(self.names)
        }
        plot = Path(run_dir) / self.cfg.plot_name
        self._plot(plot, reached)
        return {
            "success_rate": float(self.success.float().mean()),
            "reached_phase_fraction": reached,
            "highest_phase_histogram": {
                name: int((self.max_phase == p).sum()) for p, name in enumerate(self.names)
            },
            "landed_short_fraction": float(self.landed_short.float().mean()),
            "mean_turned_rad": float(self.turned_rad.mean()),
            "plot": str(plot),
        }

    def _plot(self, path: Path, reached: dict[str, float]) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.5))
        ax0.bar(list(reached), list(reached.values()), color="tab:blue")
        ax0.set_ylim(0, 1)
        ax0.set_ylabel("fraction of episodes reaching")
        ax0.set_title(f"success rate {float(self.success.float().mean()):.2f}")
        if self.occupancy:
            occ = np.asarray(self.occupancy)
            t = np.arange(occ.shape[0]) * self._env.step_dt_s
            ax1.stackplot(t, occ.T, labels=self.names)
            ax1.legend(loc="upper right", fontsize=7)
        ax1.set_xlabel("time [s]")
        ax1.set_ylabel("fraction of envs in phase")
        fig.tight_layout()
        atomic_savefig(fig, path, dpi=100)
        plt.close(fig)


def backflip_task(artifact_path: str | Path | None = None) -> TaskConfig:
    """The backflip task; desired joint poses per phase from the backflip oracle artifact at
    ``artifact_path`` (checked now), else the built-in poses. The description names the source."""
    source = bt.BUILTIN_POSES
    if artifact_path is not None:
        source = str(artifact_path)
        bt.desired_joint_poses(source)  # fail here, with the artifact's message, not mid-run
    poses = (
        "built-in unless the pose_deviation term's source names an oracle artifact"
        if source == bt.BUILTIN_POSES
        else f"oracle artifact {source}"
    )
    return dataclasses.replace(
        _BACKFLIP,
        description=f"{_BACKFLIP.description}; desired joint poses: {poses}",
        rewards=tuple(
            dataclasses.replace(t, params={"source": source}) if t.name == "pose_deviation" else t
            for t in _BACKFLIP.rewards
        ),
    )


_BACKFLIP = TaskConfig(
    name="backflip",
    description="standing backflip, FSM stand/crouch/jump/air/land started by c_t = 1_start",
    observations=PROPRIOCEPTIVE_OBSERVATIONS,
    rewards=(
        # Task (paper table), each masked to its phase.
        RewardTerm("alive", bt.phase_alive, weight=2.0, params={"phases": (bt.STAND,)}),
        RewardTerm(
            "down_velocity",
            bt.down_velocity_in_contact,
            weight=2.0,
            params={"phases": (bt.CROUCH,)},
        ),
        RewardTerm("up_velocity", bt.up_velocity, weight=2.0, params={"phases": (bt.JUMP,)}),
        RewardTerm(
            "pitch_rate_jump", bt.backward_pitch_rate, weight=0.5, params={"phases": (bt.JUMP,)}
        ),
        RewardTerm(
            "pitch_rate_air", bt.backward_pitch_rate, weight=2.0, params={"phases": (bt.AIR,)}
        ),
        RewardTerm(
            "land", bt.land_still, weight=20.0, params={"phases": (bt.LAND,), "scale": 10.0}
        ),
        # Regularisation.
        RewardTerm("balance_ground", bt.tilt_angle, weight=-2.0, params={"phases": GROUND}),
        RewardTerm("balance_flight", bt.lateral_axis_angle, weight=-2.0, params={"phases": FLIGHT}),
        RewardTerm("yaw_rate", bt.yaw_rate_abs, weight=-0.1),
        RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.01),
        RewardTerm("joint_acc", rewards.joint_acc_l2, weight=-2.5e-7),
        RewardTerm("joint_limits", rewards.joint_pos_limits, weight=-1.0),
        RewardTerm(
            "pose_deviation",
            bt.phase_pose_deviation,
            weight=-0.2,
            params={"source": bt.BUILTIN_POSES},
        ),
    ),
    terminations=(
        TerminationTerm("link_on_ground", terminations.link_on_ground),
        TerminationTerm("too_low", terminations.base_too_low, params={"min_height_m": 0.3}),
        TerminationTerm(
            "fell", bt.tilted_in_phases, params={"max_tilt_rad": 1.0, "phases": GROUND}
        ),
    ),
    assist_bound=paper_bound_rows("backflip"),
    episode_length_s=4.0,
    initial_state=InitialStateConfig(
        joint_pos_noise_rad=0.05, base_vel_noise=0.05, random_yaw=False
    ),
    pushes=PushConfig(enabled=False),
    randomization=RandomizationConfig(com_offset_range_m=(0.0, 0.0)),
    commands=bt.StartCommandConfig(delay_range_s=(0.3, 1.0)),
    phases=bt.BackflipPhasesConfig(),
    skill=bt.BackflipSkillConfig(hold_s=1.0),
    less_assist_weight=1.0,
    evaluation=BackflipEvaluationConfig(),
)

BACKFLIP = backflip_task()
"""The registered backflip task (built-in desired poses)."""
