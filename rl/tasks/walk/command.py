"""The walk's velocity command: (vx, vy, yaw rate) drawn uniformly, resampled every few seconds,
a share of envs told to stand, an optional gait clock, and a command curriculum."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from rl.envs.components import Command, CommandColumns
from rl.envs.state import EnvState


@dataclass(frozen=True)
class VelocityCommandConfig:
    """Uniform velocity commands in the pelvis frame, resampled within the episode; optionally a
    gait clock (appended to the command) and a command curriculum (ranges widened while the
    robots track)."""

    lin_vel_x_range_mps: tuple[float, float] = (-0.6, 1.2)  # forward velocity [m/s]
    lin_vel_y_range_mps: tuple[float, float] = (-0.8, 0.8)  # lateral velocity [m/s]
    ang_vel_z_range_rps: tuple[float, float] = (-1.5, 1.5)  # yaw rate [rad/s]
    resampling_time_range_s: tuple[float, float] = (4.0, 8.0)  # time between two draws [s]
    standing_fraction: float = 0.1  # share of draws that command standing still (zeros) [-]
    pure_fraction: float = 0.0  # share of moving draws that keep one of vx, vy, yaw rate [-]
    gait_period_s: float = 0.0  # period of the gait clock appended as (sin, cos); 0: no clock [s]
    curriculum_initial_scale: float = 1.0  # ranges start at this fraction of the above [-]
    curriculum_error_mps: float = 0.25  # ranges widen while the mean velocity error is below [m/s]
    curriculum_rate_per_s: float = 0.01  # widening of the scale per second of env time [1/s]

    def __post_init__(self) -> None:
        for name in (
            "lin_vel_x_range_mps",
            "lin_vel_y_range_mps",
            "ang_vel_z_range_rps",
            "resampling_time_range_s",
        ):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"velocity command {name} must be (low, high), got {(low, high)}")
        if self.resampling_time_range_s[0] <= 0:
            raise ValueError("velocity command resampling_time_range_s must be > 0 s")
        if not 0.0 <= self.standing_fraction <= 1.0:
            raise ValueError(
                f"velocity command standing_fraction must be in [0, 1], got {self.standing_fraction}"
            )
        if not 0.0 <= self.pure_fraction <= 1.0:
            raise ValueError(
                f"velocity command pure_fraction must be in [0, 1], got {self.pure_fraction}"
            )
        if self.gait_period_s < 0:
            raise ValueError(
                f"velocity command gait_period_s must be >= 0, got {self.gait_period_s}"
            )
        if not 0.0 < self.curriculum_initial_scale <= 1.0:
            raise ValueError(
                "velocity command curriculum_initial_scale must be in (0, 1], got "
                f"{self.curriculum_initial_scale}"
            )

    @property
    def dim(self) -> int:
        """Command width C: vx, vy, yaw rate (+ sin, cos of the gait clock) [-]."""
        return 5 if self.gait_period_s > 0 else 3

    def build(self, num_envs: int, generator: torch.Generator) -> VelocityCommand:
        """The live command generator (draws from the env's generator)."""
        return VelocityCommand(self, num_envs, generator)


@dataclass(frozen=True)
class CommandSegment:
    """One leg of a scripted command sequence: a name, how long, and (vx, vy, yaw rate)."""

    name: str
    """what the segment asks for (a row of the per-command table) [-]"""
    duration_s: float
    """how long the segment lasts [s]"""
    command: tuple[float, float, float]
    """(vx [m/s], vy [m/s], yaw rate [rad/s]) in the pelvis frame"""


class VelocityCommand(Command):
    """Per-env (vx, vy, yaw rate) with a countdown to the next draw, the gait clock and the
    command curriculum's scale; see the config."""

    def __init__(self, cfg: VelocityCommandConfig, num_envs: int, generator: torch.Generator):
        self.cfg = cfg
        self.generator = generator
        self.device = dev = generator.device  # the env's device: tensors and draws live there
        self.command = torch.zeros(num_envs, cfg.dim, device=dev)
        self.time_left_s = torch.zeros(num_envs, device=dev)
        self.clock_s = torch.zeros(num_envs, device=dev)  # time since the episode's start [s]
        self.scale = torch.tensor(cfg.curriculum_initial_scale, device=dev)  # curriculum [-]
        self.error_mps = torch.tensor(0.0, device=dev)  # running mean velocity error (0.5 s)
        ranges = (cfg.lin_vel_x_range_mps, cfg.lin_vel_y_range_mps, cfg.ang_vel_z_range_rps)
        self._low = torch.tensor([r[0] for r in ranges], device=dev)
        self._high = torch.tensor([r[1] for r in ranges], device=dev)
        self._script: tuple[torch.Tensor, torch.Tensor] | None = None  # (K,) ends [s], (K, 3)
        self._held: tuple[torch.Tensor, torch.Tensor] | None = None  # (N,) bool, (N, 3)

    def follow_script(self, segments: tuple[CommandSegment, ...]) -> None:
        """From now on every env follows ``segments`` in order by its episode time (the last one
        held), instead of random draws (an evaluation's scripted sequence; no draws are made)."""
        if not segments:
            raise ValueError("a command script needs at least one segment")
        durations = torch.tensor([seg.duration_s for seg in segments], device=self.device)
        commands = torch.tensor([seg.command for seg in segments], device=self.device)
        self._script = (durations.cumsum(0), commands)
        self._scripted()

    def hold(self, held: torch.Tensor, commands: torch.Tensor) -> None:
        """From now on the envs where ``held`` (N,) is true keep ``commands`` (N, 3) (vx, vy, yaw
        rate) whatever their draws; the others draw as before (an evaluation per command kind)."""
        self._held = (held.to(self.device), commands.to(self.device, torch.float32))
        self._apply_held()

    def _apply_held(self) -> None:
        if self._held is not None:
            held, commands = self._held
            self.command[:, :3] = torch.where(held[:, None], commands, self.command[:, :3])

    def segment(self) -> torch.Tensor | None:
        """(N,) long: the script segment each env is in (None without a script)."""
        if self._script is None:
            return None
        ends = self._script[0]
        return torch.searchsorted(ends, self.clock_s, right=True).clamp(max=len(ends) - 1)

    def describe(self, env: int) -> str:
        """Env ``env``'s command, e.g. "command: vx +0.50 m/s  vy +0.00 m/s  yaw +0.00 rad/s"."""
        vx, vy, wz = (float(c) for c in self.command[env, :3])
        return f"command: vx {vx:+.2f} m/s  vy {vy:+.2f} m/s  yaw {wz:+.2f} rad/s"

    def _scripted(self) -> None:
        self.command[:, :3] = self._script[1][self.segment()]

    def resample(self, env_ids: torch.Tensor) -> None:
        """Draw new commands and countdowns for ``env_ids`` (M,) within the scaled ranges."""
        m, gen = env_ids.numel(), self.generator
        if (
            m == 0 or self._script is not None
        ):  # a script sets the commands by time (compute, reset)
            return
        low, high = self._low * self.scale, self._high * self.scale
        draw = low + (high - low) * torch.rand(m, 3, generator=gen, device=self.device)
        standing = torch.rand(m, generator=gen, device=self.device) < self.cfg.standing_fraction
        if self.cfg.pure_fraction > 0:  # one axis kept: forward or back, sideways, turn in place
            pure = torch.rand(m, generator=gen, device=self.device) < self.cfg.pure_fraction
            axis = torch.randint(0, 3, (m,), generator=gen, device=self.device)
            keep = torch.nn.functional.one_hot(axis, 3).bool() | ~pure[:, None]
            draw = torch.where(keep, draw, torch.zeros_like(draw))
        self.command[env_ids, :3] = torch.where(standing[:, None], torch.zeros_like(draw), draw)
        self._apply_held()
        t_low, t_high = self.cfg.resampling_time_range_s
        self.time_left_s[env_ids] = t_low + (t_high - t_low) * torch.rand(
            m, generator=gen, device=self.device
        )

    def reset(self, env_ids: torch.Tensor) -> None:
        """A new episode starts with a new command and the clock at 0."""
        self.resample(env_ids)
        self.clock_s[env_ids] = 0.0
        if self._script is not None:
            self._scripted()
        self._write_clock()

    def _write_clock(self) -> None:
        if self.cfg.gait_period_s > 0:
            angle = 2 * torch.pi * (self.clock_s / self.cfg.gait_period_s % 1.0)
            self.command[:, 3] = torch.sin(angle)
            self.command[:, 4] = torch.cos(angle)

    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Count down by ``dt_s`` [s], redraw the expired commands, advance the clock and the
        curriculum; (N, C)."""
        cfg = self.cfg
        if dt_s > 0 and self.scale < 1.0:
            error = (state.base_lin_vel_b[:, :2] - self.command[:, :2]).norm(dim=-1).mean()
            self.error_mps += (error - self.error_mps) * min(dt_s / 0.5, 1.0)
            if self.error_mps < cfg.curriculum_error_mps:
                self.scale = (self.scale + cfg.curriculum_rate_per_s * dt_s).clamp(max=1.0)
        self.time_left_s -= dt_s
        self.resample((self.time_left_s <= 0).nonzero().flatten())
        self.clock_s += dt_s
        if self._script is not None:
            self._scripted()
        self._write_clock()
        return self.command

    def columns(self) -> tuple[CommandColumns, ...]:
        """Velocity (vx, vy, yaw rate) in the pelvis frame, then the gait clock (sin, cos)."""
        blocks = (
            CommandColumns("lin_vel_x", 1, "m/s", "forward velocity to walk at, pelvis frame"),
            CommandColumns("lin_vel_y", 1, "m/s", "lateral velocity (left positive), pelvis frame"),
            CommandColumns("ang_vel_z", 1, "rad/s", "yaw rate (counter-clockwise positive)"),
        )
        if self.cfg.gait_period_s > 0:
            blocks += (
                CommandColumns(
                    "gait_clock", 2, "-",
                    f"sin, cos of 2 pi t / {self.cfg.gait_period_s:g} s, t: time since the "
                    "policy started [s] (the left foot's gait phase; the right foot is half a "
                    "period later)",
                ),
            )  # fmt: skip
        return blocks

    def for_evaluation(self) -> None:
        """Evaluations draw from the full command ranges."""
        self.scale = torch.tensor(1.0, device=self.device)

    def log(self) -> dict[str, float]:
        """``Curriculum/command_scale`` (when the curriculum is on)."""
        return (
            {"Curriculum/command_scale": float(self.scale)}
            if self.cfg.curriculum_initial_scale < 1
            else {}
        )

    def state_dict(self) -> dict[str, Any]:
        """Commands, countdowns, clocks and the curriculum."""
        return {
            "command": self.command.clone(),
            "time_left_s": self.time_left_s.clone(),
            "clock_s": self.clock_s.clone(),
            "scale": self.scale.clone(),
            "error_mps": self.error_mps.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.command.copy_(state["command"])
        self.time_left_s.copy_(state["time_left_s"])
        self.clock_s.copy_(state["clock_s"])
        self.scale = state["scale"].to(self.device, copy=True)
        self.error_mps = state["error_mps"].to(self.device, copy=True)
