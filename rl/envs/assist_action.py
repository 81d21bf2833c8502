"""The assist half of the action as the env applies it: bound, squash, mask, frame, the applied
wrench, the less-assist reward and the curriculum's statistics (the env's assist part)."""

from __future__ import annotations

from typing import Any

import torch

from rl import rewards
from rl.assist import DEFAULT_RANDOM_MASK_PROB, WRENCH_DIM, AssistState
from rl.curriculum import WRENCH_AXES, CurriculumEvent
from rl.envs.state import heading_to_world


class AssistAction:
    """The assist wrench: what actions[:, 29:35] (the assist head's raw, unbounded output) do.

    **The frame of the assist wrench, stated here once.** The applied wrench is
    ``F = mask * eta[phase] * tanh(raw)`` (N, 6): force [N] then torque [Nm] at the pelvis centre
    of mass, in each robot's *heading frame*: x forward along the pelvis yaw, y to its left, z up
    (world vertical). Each mask component is 0 with probability zeta, redrawn every step; F = 0
    while assistance is off. For MuJoCo's ``xfrc_applied`` (world frame) :meth:`to_world` turns F
    about z by the pelvis yaw at the start of the step; it is held over the step's substeps.

    Everything that reads or writes F is in this frame: ``applied_wrench`` (here, in
    :class:`rl.envs.state.EnvState` and ``extras["assist"]``), the bound eta (num_phases, 6) and
    its axes :data:`rl.curriculum.WRENCH_AXES`, the curriculum's per-axis statistics, the
    less-assist reward, the coaches' labels (:mod:`rl.coaches`, :mod:`rl.warmstart`) and the
    oracle's eta0 (:mod:`optimal_control.bounds`, derived on the reference's heading axes).

    Why the heading frame: episodes start at a random yaw and nothing the force agent observes
    tells it the heading, so a world-frame ``fx`` would be a different push for every robot; in the
    heading frame ``fx`` is always a forward push and ``my`` the pitch torque a backflip needs
    (the paper's per-axis bounds read that way).
    """

    def __init__(
        self,
        bound: torch.Tensor,
        num_envs: int,
        phase_names: tuple[str, ...],
        less_assist_weight: float,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """Start with eta = ``bound`` (num_phases, 6) [N, Nm], assistance on, the paper's zeta
        and no less-assist reward (the runner sets its mode's switches). Every tensor, eta
        included, lives on ``device`` (the generator's)."""
        self.device = device
        self.settings = AssistState(
            torch.as_tensor(bound).to(device),
            enabled=True,
            mask_prob=DEFAULT_RANDOM_MASK_PROB,
            less_assist_reward=False,
            generator=generator,
        )
        self.phase_names, self.less_assist_weight = phase_names, less_assist_weight
        # F of this step, 0 after a reset; the mask of this step; envs that never get help
        self.applied_wrench = torch.zeros(num_envs, WRENCH_DIM, device=device)
        self.mask = torch.ones(num_envs, WRENCH_DIM, device=device)
        self.alone = torch.zeros(num_envs, dtype=torch.bool, device=device)
        self.curriculum_event: CurriculumEvent | None = None
        self.step_extras: dict[str, torch.Tensor] = {}  # extras["assist"] of the last step

    @property
    def bound(self) -> torch.Tensor:
        """eta (num_phases, 6) [N, Nm]."""
        return self.settings.bound

    def observed_bound(self, phase: torch.Tensor) -> torch.Tensor:
        """The bound each env's help is under (N, 6) [N, Nm] for envs in ``phase`` (N,): eta of
        its phase, zero for the alone envs (what the privileged and critic observations show:
        an alone env showing the helped envs' bound would look helped to the critic)."""
        bound = self.settings.bound[phase]
        return bound.masked_fill(self.alone[:, None], 0.0) if self.alone.any() else bound

    def set_bound(self, eta: torch.Tensor) -> None:
        """Set eta (num_phases, 6) [N, Nm], the per-phase, per-axis bound."""
        self.settings.set_bound(torch.as_tensor(eta).detach())  # moved to this part's device

    def set_enabled(self, enabled: bool) -> None:
        """Switch the wrench on or off (off: F = 0 whatever the head outputs)."""
        self.settings.enabled = bool(enabled)

    def set_mask_prob(self, zeta: float) -> None:
        """Set zeta, the probability of dropping each wrench component every step."""
        self.settings.set_mask_prob(zeta)

    def set_less_assist_reward(self, enabled: bool) -> None:
        """Pay (or stop paying) the less-assist reward (:meth:`rewards`)."""
        self.settings.less_assist_reward = bool(enabled)

    def attach_curriculum(self, event: CurriculumEvent | None, task_name: str) -> None:
        """Run Algorithm 1 from this part's statistics and apply its current state now; ``None``
        detaches it (the last bounds stay)."""
        self.curriculum_event = event
        share = event.curriculum.cfg.alone_share if event is not None else 0.0
        num = self.alone.numel()
        self.alone = torch.arange(num, device=self.device) < round(share * num)
        if event is not None:
            if event.curriculum.num_phases != len(self.phase_names):
                raise ValueError(
                    f"curriculum has {event.curriculum.num_phases} phases, task '{task_name}' "
                    f"has {len(self.phase_names)}"
                )
            self._apply_curriculum()

    def _apply_curriculum(self) -> None:
        cur = self.curriculum_event.curriculum
        self.set_bound(cur.eta)
        self.set_enabled(cur.assist_enabled)
        self.set_less_assist_reward(cur.less_assist_reward)

    def apply(self, raw: torch.Tensor, phase: torch.Tensor) -> torch.Tensor:
        """F (N, 6) in the heading frame for raw head outputs (N, 6) of envs in ``phase`` (N,)."""
        wrench, bound, self.mask = self.settings.wrench(raw, phase)
        if self.alone.any():
            wrench[self.alone] = 0.0
        self.applied_wrench = wrench.clone()
        self.step_extras = {"applied_wrench": wrench, "bound": bound, "phase": phase}
        return wrench

    def to_world(self, quat_wxyz: torch.Tensor) -> torch.Tensor:
        """This step's F as world-frame wrenches (N, 6) for pelvis orientations (N, 4) w x y z."""
        return heading_to_world(self.step_extras["applied_wrench"], quat_wxyz)

    def reset(self, env_ids: torch.Tensor) -> None:
        """No wrench on ``env_ids`` (M,) until their next step."""
        self.applied_wrench[env_ids] = 0.0

    def rewards(self, step_dt_s: float) -> dict[str, torch.Tensor]:
        """This part's weighted reward terms (N,) of this step: ``less_assist``,
        exp(-2|F|/|eta|) x weight x dt, while switched on (else none)."""
        if not self.settings.less_assist_reward:
            return {}
        extras = self.step_extras
        value = rewards.less_assist(extras["applied_wrench"], extras["bound"])
        return {"less_assist": value * (self.less_assist_weight * step_dt_s)}

    def log(self) -> dict[str, float]:
        """Mean force and torque norms of this step."""
        wrench = self.step_extras["applied_wrench"]
        return {
            "Assist/force_norm_n": float(wrench[:, :3].norm(dim=-1).mean()),
            "Assist/torque_norm_nm": float(wrench[:, 3:].norm(dim=-1).mean()),
        }

    def curriculum_step(
        self, skill_progress: float, alone_progress: float | None = None
    ) -> dict[str, float]:
        """Hand this step (the helped envs' rows) to the curriculum; at a rollout's end apply its
        update and return the update's log (else ``{}``)."""
        if self.curriculum_event is None:
            return {}
        extras = self.step_extras
        if self.alone.any():
            extras = {key: value[~self.alone] for key, value in extras.items()}
        row = self.curriculum_event.on_step(extras, skill_progress, alone_progress)
        if row is None:
            return {}
        self._apply_curriculum()
        log = {
            "Curriculum/applied_force_n": float(row["applied_force_n"]),
            "Curriculum/skill_progress": float(row["skill_progress"]),
            **(
                {"Curriculum/skill_progress_alone": float(row["alone_progress"])}
                if row["alone_progress"] is not None
                else {}
            ),  # fmt: skip
            "Curriculum/assist_enabled": float(row["assist_enabled"]),
            "Curriculum/less_assist_reward": float(row["less_assist_reward"]),
        }
        for phase, bounds, norm, applied in zip(
            self.phase_names, row["eta"], row["applied_norm"], row["applied_abs_per_axis"],
            strict=True,
        ):  # fmt: skip
            for axis, value, used in zip(WRENCH_AXES, bounds, applied, strict=True):
                log[f"Curriculum/eta_{phase}_{axis}"] = float(value)
                log[f"Curriculum/applied_abs_{phase}_{axis}"] = float(used)
            log[f"Curriculum/applied_wrench_norm_{phase}"] = float(norm)
        return log

    def state_dict(self) -> dict[str, Any]:
        """Settings, this step's wrench and mask, and the curriculum event."""
        event = self.curriculum_event
        return {
            "bound": self.settings.bound.clone(),
            "enabled": self.settings.enabled,
            "mask_prob": self.settings.mask_prob,
            "less_assist_reward": self.settings.less_assist_reward,
            "applied_wrench": self.applied_wrench.clone(),
            "mask": self.mask.clone(),
            "curriculum_event": event.state_dict() if event is not None else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (a saved curriculum needs one attached)."""
        self.settings.set_bound(state["bound"])
        self.settings.enabled = bool(state["enabled"])
        self.settings.set_mask_prob(state["mask_prob"])
        self.settings.less_assist_reward = bool(state["less_assist_reward"])
        self.applied_wrench = state["applied_wrench"].to(self.device, copy=True)
        self.mask = state["mask"].to(self.device, copy=True)
        if state["curriculum_event"] is not None:
            if self.curriculum_event is None:
                raise ValueError("env checkpoint has a curriculum; attach one before loading")
            self.curriculum_event.load_state_dict(state["curriculum_event"])
