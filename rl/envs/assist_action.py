"""The assist half of the action as the env applies it: bound, squash, mask, frame, the applied
wrench and the less-assist reward (the env's assist part; Algorithm 1 is the runner's,
:mod:`rl.a2cf.algorithm1`)."""

from __future__ import annotations

from typing import Any

import torch

from rl.envs.assist import DEFAULT_RANDOM_MASK_PROB, WRENCH_DIM, AssistState, less_assist
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
    its axes :data:`rl.envs.assist.WRENCH_AXES`, the curriculum's per-axis statistics, the
    less-assist reward, the coaches' labels (:mod:`rl.a2cf.coaches`, :mod:`rl.a2cf.warmstart`) and the
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
        self._any_alone = False  # whether ``alone`` has a True row, kept on the host (no sync)
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
        return bound.masked_fill(self.alone[:, None], 0.0) if self._any_alone else bound

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

    def set_alone_share(self, share: float) -> None:
        """Keep the first ``share`` of the envs without help (the alone envs); 0: none."""
        num = self.alone.numel()
        self.alone = torch.arange(num, device=self.device) < round(share * num)
        self._any_alone = round(share * num) > 0

    def apply(self, raw: torch.Tensor, phase: torch.Tensor) -> torch.Tensor:
        """F (N, 6) in the heading frame for raw head outputs (N, 6) of envs in ``phase`` (N,)."""
        wrench, bound, self.mask = self.settings.wrench(raw, phase)
        if self._any_alone:
            wrench.masked_fill_(self.alone[:, None], 0.0)
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
        value = less_assist(extras["applied_wrench"], extras["bound"])
        return {"less_assist": value * (self.less_assist_weight * step_dt_s)}

    def log(self) -> dict[str, torch.Tensor]:
        """Mean force and torque norms of this step (0-dim tensors on the device: the env sends
        its log to the host in one batch)."""
        wrench = self.step_extras["applied_wrench"]
        return {
            "Assist/force_norm_n": wrench[:, :3].norm(dim=-1).mean(),
            "Assist/torque_norm_nm": wrench[:, 3:].norm(dim=-1).mean(),
        }

    def state_dict(self) -> dict[str, Any]:
        """Settings, this step's wrench and mask."""
        return {
            "bound": self.settings.bound.clone(),
            "enabled": self.settings.enabled,
            "mask_prob": self.settings.mask_prob,
            "less_assist_reward": self.settings.less_assist_reward,
            "applied_wrench": self.applied_wrench.clone(),
            "mask": self.mask.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.settings.set_bound(state["bound"])
        self.settings.enabled = bool(state["enabled"])
        self.settings.set_mask_prob(state["mask_prob"])
        self.settings.less_assist_reward = bool(state["less_assist_reward"])
        self.applied_wrench = state["applied_wrench"].to(self.device, copy=True)
        self.mask = state["mask"].to(self.device, copy=True)
