"""The motion half of the action as the env applies it: joint PD targets around the standing pose,
or around a reference pose the caller gives each step (the env's motion-action part)."""

from __future__ import annotations

import torch

from rl.envs.declared_state import DeclaredState
from robots import g1


class MotionAction(DeclaredState):
    """actions[:, :29] = a (N, 29) [-]: joint PD targets ``base + ACTION_SCALE_RAD * a`` [rad], with
    ``base`` the standing pose or the (N, 29) pose given with the action (a tracking task's
    reference joints); the action of this step and of the previous one (what observations and
    rewards read)."""

    state_attributes = ("action", "last_action")
    """Saved and restored by :class:`~rl.envs.declared_state.DeclaredState`."""

    def __init__(self, num_envs: int, device: torch.device | str = "cpu") -> None:
        """Both actions start at 0 (the standing pose); every tensor lives on ``device``."""
        self.device = device
        self.stand_rad = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32, device=device)
        self.scale = torch.as_tensor(g1.ACTION_SCALE_RAD, dtype=torch.float32, device=device)
        self._kd_over_kp = torch.as_tensor(g1.KD / g1.KP, dtype=torch.float32, device=device)
        self._inv_kp = torch.as_tensor(1.0 / g1.KP, dtype=torch.float32, device=device)
        self.action = torch.zeros(num_envs, g1.NUM_JOINTS, device=device)
        self.last_action = torch.zeros(num_envs, g1.NUM_JOINTS, device=device)

    def apply(self, action: torch.Tensor, base_rad: torch.Tensor | None = None) -> torch.Tensor:
        """Take this step's action (N, 29); returns the PD targets (N, 29) [rad] around
        ``base_rad`` (N, 29) [rad] (``None``: the standing pose)."""
        self.action = action
        return (self.stand_rad if base_rad is None else base_rad) + self.scale * action

    def feedforward_rad(self, joint_vel_rps: torch.Tensor, torque_nm: torch.Tensor) -> torch.Tensor:
        """The PD-target shift (N, 29) [rad] that adds ``kd * joint_vel_rps + torque_nm`` to the
        PD law ``kp (target - q) - kd qd``: velocity and torque feed-forward through the
        position actuator (kd/kp qd_ref + tau_ref/kp)."""
        return self._kd_over_kp * joint_vel_rps + self._inv_kp * torque_nm

    def end_step(self) -> None:
        """This step's action becomes the last one."""
        self.last_action = self.action.clone()

    def to_actions(
        self, joint_pos_rad: torch.Tensor, base_rad: torch.Tensor | None = None
    ) -> torch.Tensor:
        """The actions (N, 29) whose PD targets around ``base_rad`` (as in :meth:`apply`) are
        ``joint_pos_rad`` (N, 29) [rad]."""
        base = self.stand_rad if base_rad is None else base_rad.float()
        return (joint_pos_rad.float() - base) / self.scale

    def reset(self, env_ids: torch.Tensor) -> None:
        """Zero both actions of ``env_ids`` (M,)."""
        self.action[env_ids] = 0.0
        self.last_action[env_ids] = 0.0


def checked_actions(
    actions: torch.Tensor, shape: tuple[int, int], clip: float, device: torch.device | str
) -> tuple[torch.Tensor, torch.Tensor]:
    """``actions`` (N, 35) as float32 on ``device``, non-finite entries zeroed (MuJoCo would
    reset them; returned: how many rows had one, a 0-dim tensor on ``device``: no host read) and
    clipped to ``[-clip, clip]``; a wrong shape is one line."""
    if tuple(actions.shape) != shape:
        raise ValueError(
            f"G1VecEnv.step expects actions of shape {shape} = (num_envs, 29 joint + 6 assist), "
            f"got {tuple(actions.shape)}."
        )
    actions = actions.detach().to(device, torch.float32)
    nonfinite = (~torch.isfinite(actions).all(dim=-1)).sum()
    # unconditional: finite entries pass unchanged, so no host read decides whether to run it
    actions = torch.nan_to_num(actions, nan=0.0, posinf=0.0, neginf=0.0)
    return actions.clamp(-clip, clip), nonfinite
