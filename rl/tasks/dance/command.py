"""The dance's clip-tracking command: per env a clip and a start frame; the command targets the
reference's next frame (layout: :mod:`rl.tasks.dance.terms`).

Each episode tracks one clip, drawn uniformly, from a start frame drawn uniformly along it
(no emphasis on hard segments); past the clip's end the last frame is held.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from rl.envs.components import Command, CommandColumns
from rl.envs.state import EnvState
from rl.tasks.dance.clips import BUILTIN_CLIP, clip_library
from rl.tasks.dance.terms import COMMAND_DIM, joint_error_mean_abs
from robots import g1


@dataclass(frozen=True)
class ClipTrackingConfig:
    """Clip-tracking command: the clips and the policy step their frames must have."""

    sources: tuple[str, ...] = (BUILTIN_CLIP,)  # "builtin" and/or CSV / NPZ clip paths [-]
    step_dt_s: float = 0.02  # policy step = clip frame step (env decimation x physics dt) [s]
    dim: int = COMMAND_DIM  # command width [dp 3, dq 4, q 29] [-]
    min_frames_left: int = 50  # start frames leave at least this many frames to track [-]

    def build(self, num_envs: int, generator: torch.Generator) -> ClipTrackingCommand:
        """The live command (loads the clips once per process)."""
        return ClipTrackingCommand(self, num_envs, generator)


class ClipTrackingCommand(Command):
    """Per env: clip, start frame and steps since the reset; puts reset robots on their frame."""

    log_key = "Dance/joint_error_rad"  # the per-step mean joint error in the training log

    def __init__(self, cfg: ClipTrackingConfig, num_envs: int, generator: torch.Generator) -> None:
        self.cfg = cfg
        self.generator = generator
        self.device = dev = generator.device  # the env's device: buffers and draws live there
        self.library = lib = self._load_library(cfg)
        # What every step reads, on the env's device once; the poses a reset takes (numpy
        # rows of the library) cross from the host at resets only.
        self._start, self._length = lib.start.to(dev), lib.length.to(dev)
        self._command = lib.command.to(dev)
        self.clip = torch.zeros(num_envs, dtype=torch.long, device=dev)
        self.start_frame = torch.zeros(num_envs, dtype=torch.long, device=dev)  # global index
        self.steps = torch.zeros(num_envs, dtype=torch.long, device=dev)
        self.z_offset_m = torch.zeros(num_envs, dtype=torch.float64, device=dev)
        self.fresh = torch.ones(num_envs, dtype=torch.bool, device=dev)
        self._error_sum = 0.0
        self._error_count = 0

    def _load_library(self, cfg: Any) -> Any:
        """The (per-process cached) clip library of ``cfg``'s sources."""
        return clip_library(cfg.sources, cfg.step_dt_s)

    def _sample(self, env_ids: torch.Tensor) -> None:
        lib, m, dev = self.library, env_ids.numel(), self.device
        clip = torch.randint(len(lib.names), (m,), generator=self.generator, device=dev)
        length = self._length[clip]
        span = (length - self.cfg.min_frames_left).clamp_min(1)
        offset = (torch.rand(m, generator=self.generator, device=dev) * span).long()
        self.clip[env_ids] = clip
        self.start_frame[env_ids] = self._start[clip] + offset
        self.steps[env_ids] = 0

    def reset_state(
        self,
        env_ids: torch.Tensor,
        qpos: torch.Tensor,
        qvel: torch.Tensor,
        generator: torch.Generator,
    ) -> None:
        """Draw clip and start frame; the robot takes that frame's pose and velocity, lowered
        (or raised) so its lowest sole corner is where the standing robot's is: on the floor."""
        self._sample(env_ids)
        frames = self.start_frame[env_ids].cpu().numpy()  # the host library: a reset-time copy
        lib = self.library
        rows = torch.as_tensor(lib.qpos[frames]).clone()
        shift = torch.as_tensor(lib.floor_shift_m[frames])
        rows[:, 2] -= shift
        self.z_offset_m[env_ids] = -shift.to(self.device)
        qpos[:] = rows.to(qpos.device)
        qvel[:] = torch.as_tensor(lib.qvel[frames]).to(qvel.device)

    def reset(self, env_ids: torch.Tensor) -> None:
        """The next :meth:`compute` keeps these envs on their start frame."""
        self.fresh[env_ids] = True

    def frame(self, ahead: int = 0) -> torch.Tensor:
        """Global frame index (N,) of each env's reference ``ahead`` steps on (held at the end)."""
        start = self._start[self.clip]
        local = self.start_frame - start + self.steps + ahead
        return start + local.clamp_max(self._length[self.clip] - 1)

    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Advance the reference by one step (not for envs reset this step) and return the
        command targeting the next frame (N, 36); past the clip's end: hold the last pose."""
        if abs(state.step_dt_s - self.cfg.step_dt_s) > 1e-9:
            raise ValueError(
                f"dance clips are sampled at step_dt_s = {self.cfg.step_dt_s} s but the env steps "
                f"{state.step_dt_s} s: set the task's commands.step_dt_s to the env's step"
            )
        if (~self.fresh).any() and state.command.shape[1] == COMMAND_DIM:
            err = joint_error_mean_abs(state)[~self.fresh]
            self._error_sum += float(err.sum())
            self._error_count += int(err.numel())
        self.steps += (~self.fresh).long()
        self.fresh[:] = False
        nxt = self.frame(ahead=1)
        command = self._command[nxt].clone()
        at_end = nxt == self.frame(ahead=0)
        command[at_end, :3] = 0.0
        command[at_end, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0], device=self.device)
        return command

    def columns(self) -> tuple[CommandColumns, ...]:
        """The reference frame after this step: base step displacement, step rotation, joints."""
        frame = (
            "of the clip frame the robot should reach after this policy step (clips at the "
            "policy rate, one frame per step from the episode's start frame, the last frame held "
            f"past the clip's end; clips: {', '.join(self.cfg.sources)})"
        )
        return (
            CommandColumns(
                "base_step_displacement", 3, "m",
                "pelvis displacement over one policy step (world velocity x dt, rotated into the "
                f"pelvis heading (yaw) frame: x forward, y left, z up) {frame}; 0 past the end",
            ),
            CommandColumns(
                "base_step_rotation", 4, "-",
                "pelvis rotation over one policy step, unit quaternion w x y z = exp(omega_b dt / 2) "
                f"(omega_b: pelvis angular velocity, pelvis frame) {frame}; 1 0 0 0 past the end",
            ),
            CommandColumns(
                "joint_pos_ref", g1.NUM_JOINTS, "rad",
                f"joint angles (absolute, not minus default_pos_rad; order of `joints`) {frame}",
            ),
        )  # fmt: skip

    def reference_time_s(self) -> torch.Tensor:
        """Per env, the time of its current frame along its clip (N,) [s] (for an oracle
        artifact's coach: the built-in dance artifact of ``solve-dance`` has the same frames)."""
        return (self.frame(0) - self._start[self.clip]).double() * self.library.dt_s

    def reference_duration_s(self, env: int = 0) -> float:
        """Length [s] of env ``env``'s clip (from its first frame to its last)."""
        return float(self._length[self.clip[env]] - 1) * self.library.dt_s

    def reference_joint_pos_rad(self) -> torch.Tensor:
        """Joint pose (N, 29) [rad] of each env's next frame (the command's joint targets)."""
        frames = self.frame(ahead=1).cpu().numpy()  # the host library (coaches, not the env step)
        return torch.as_tensor(self.library.qpos[frames, 7:]).float().to(self.device)

    def reference_pose(self, ahead: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        """Reference pelvis position (N, 3) [m] (with each env's floor offset) and orientation
        (N, 4) w x y z of the frame ``ahead`` steps on."""
        frames = self.frame(ahead).cpu().numpy()  # the host library (evaluation, coaches)
        qpos = torch.as_tensor(self.library.qpos[frames]).to(self.device, copy=True)
        qpos[:, 2] += self.z_offset_m
        return qpos[:, :3].float(), qpos[:, 3:7].float()

    def reference_qpos(self) -> np.ndarray:
        """MuJoCo qpos (N, 36) of each env's current frame, with its floor offset (videos)."""
        frames = self.frame(0).cpu().numpy()
        qpos = self.library.qpos[frames].copy()
        qpos[:, 2] += self.z_offset_m.cpu().numpy()
        return qpos

    def log(self) -> dict[str, float]:
        """Mean absolute joint tracking error of the steps since the last log [rad]."""
        if not self._error_count:
            return {}
        out = {self.log_key: self._error_sum / self._error_count}
        self._error_sum, self._error_count = 0.0, 0
        return out

    def state_dict(self) -> dict[str, Any]:
        """Per-env clip, frames, offsets."""
        return {
            "clip": self.clip.clone(),
            "start_frame": self.start_frame.clone(),
            "steps": self.steps.clone(),
            "z_offset_m": self.z_offset_m.clone(),
            "fresh": self.fresh.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the per-env buffers (onto this command's device)."""
        for key, value in state.items():
            setattr(self, key, value.to(self.device, copy=True))
