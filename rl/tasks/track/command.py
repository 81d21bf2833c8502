"""The tracking command: per env a reference and a frame along it; the command the policy sees
(layout :data:`rl.tasks.track.terms.COMMAND_DIM`) and the targets the rewards read are the
reference's *next* frame, the one the robot should reach with this step.

Training episodes start on a frame drawn by *adaptive sampling* (whole_body_tracking): each
reference is cut into bins of ``bin_s``; failures are counted per bin (a moving average), and a
start bin is drawn with probability ``uniform_share / bins`` plus the rest in proportion to its
failures (and half of the next bin's, so episodes start a little before where robots fall).
An episode ends without failing (a time-out) when it reaches its reference's last frame. In an
evaluation (:meth:`MotionCommand.for_evaluation`) env ``i`` tracks reference ``i mod K`` from its
first frame, so a skill is judged on the whole reference, not on its easy parts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from rl.envs.components import CommandColumns
from rl.envs.state import EnvState
from rl.tasks.dance.clips import BUILTIN_CLIP
from rl.tasks.dance.command import ClipTrackingCommand
from rl.tasks.track.library import motion_library
from rl.tasks.track.terms import ANCHOR, COMMAND_DIM, TRACKED_BODIES, anchor_command
from robots import g1


@dataclass(frozen=True)
class MotionCommandConfig:
    """The tracking command: references, segment, and the adaptive start sampling."""

    sources: tuple[str, ...] = (
        BUILTIN_CLIP,
    )  # "builtin", clip files (CSV / NPZ) or oracle artifact folders, one drawn per episode [-]
    frames: str = ""  # segment A:B of source frames of every reference; empty: all [-]
    step_dt_s: float = 0.02  # policy step = reference frame step (env decimation x physics dt) [s]
    dim: int = COMMAND_DIM  # command width [q 29, qd 29, anchor pos 3, anchor rot 6] [-]
    min_frames_left: int = 25  # start frames leave at least this many frames to track [-]
    bin_s: float = 1.0  # adaptive sampling bin length [s]
    uniform_share: float = 0.3  # share of start draws spread uniformly over the bins [-]
    failure_ema: float = 0.001  # per-step weight of new failures in each bin's moving count [-]
    hold_s: float = 0.0  # each reference's first and last frames held still this long [s]
    # oracle artifact solved on the reference (train --oracle): its planned torques go with it
    oracle: str = ""  # oracle artifact folder of the (one) reference; empty: none [-]
    oracle_phases: bool = False  # with oracle: its time bins are the phases (eta0 per bin) [-]

    def __post_init__(self) -> None:
        if self.frames:  # checked here; Pinocchio is imported only where a segment is given
            from optimal_control.reference_sources import parse_frames

            parse_frames(self.frames)
        if not 0.0 < self.uniform_share <= 1.0 or not 0.0 < self.failure_ema <= 1.0:
            raise ValueError(
                f"tracking uniform_share and failure_ema must be in (0, 1], got "
                f"{self.uniform_share}, {self.failure_ema}"
            )
        if self.bin_s <= 0:
            raise ValueError(f"tracking bin_s must be > 0 s, got {self.bin_s}")
        if self.oracle and len(self.sources) != 1:
            raise ValueError(
                f"an oracle artifact goes with one reference, got {len(self.sources)} "
                "(--oracle solves the oracle of a single --reference)"
            )
        if not 0.0 <= self.hold_s <= 10.0:
            raise ValueError(f"tracking hold_s must be in [0, 10] s, got {self.hold_s}")

    def build(self, num_envs: int, generator: torch.Generator) -> MotionCommand:
        """The live command (loads the references once per process)."""
        return MotionCommand(self, num_envs, generator)


class MotionCommand(ClipTrackingCommand):
    """Per env: reference, start frame, steps since the reset (the clip-tracking command's
    bookkeeping, reset poses and reference hooks), with the tracking layout and targets."""

    log_key = "Track/joint_error_rad"

    def __init__(self, cfg: MotionCommandConfig, num_envs: int, generator: torch.Generator) -> None:
        super().__init__(cfg, num_envs, generator)
        dev, lib = self.device, self.motion
        self._joint = torch.cat([lib.joint_pos_rad, lib.joint_vel_rps], dim=-1).to(dev)
        self._torque = lib.joint_torque_nm.to(dev)
        self._link_contact: tuple[int, torch.Tensor] | None = None  # (margin, (F, B) dilated)
        self._bodies = {
            "body_pos_w": lib.body_pos_w.to(dev),
            "body_quat_w": lib.body_quat_w.to(dev),
            "body_lin_vel_w": lib.body_lin_vel_w.to(dev),
            "body_ang_vel_w": lib.body_ang_vel_w.to(dev),
        }
        # adaptive sampling bins: per reference, consecutive runs of bin_frames frames
        bin_frames = max(1, round(cfg.bin_s / cfg.step_dt_s))
        starts, clips = [], []
        for k, (s0, n) in enumerate(
            zip(lib.clips.start.tolist(), lib.clips.length.tolist(), strict=True)
        ):
            for b in range(0, n, bin_frames):
                starts.append(s0 + b)
                clips.append(k)
        self._bin_start = torch.tensor(starts, device=dev)
        self._bin_clip = torch.tensor(clips, device=dev)
        self._bin_frames = bin_frames
        self.failures = torch.zeros(len(starts), dtype=torch.float64, device=dev)
        # with an oracle: the applied help per bin, summed over the steps since the last log
        self._bin_help = torch.zeros(2, len(starts), dtype=torch.float64, device=dev)
        self._ended = torch.zeros(num_envs, dtype=torch.bool, device=dev)
        self._ended_bin = torch.zeros(num_envs, dtype=torch.long, device=dev)
        self.evaluation = False
        self._targets: dict[str, torch.Tensor] = {}
        self._phase = lib.phase.to(dev)

    def _load_library(self, cfg: Any) -> Any:
        from optimal_control.reference_sources import parse_frames

        frames = parse_frames(cfg.frames)
        self.motion = motion_library(
            cfg.sources, frames, cfg.step_dt_s, cfg.hold_s, cfg.oracle, cfg.oracle_phases
        )
        return self.motion.clips

    # ------------------------------------------------------------------------------ sampling
    def _bin_of(self, frames: torch.Tensor) -> torch.Tensor:
        """The bin (B,) of global frames (N,): bins are sorted by start frame."""
        return torch.searchsorted(self._bin_start, frames, right=True) - 1

    def sampling_probabilities(self) -> torch.Tensor:
        """Per bin (B,), the probability that an episode starts in it."""
        num_bins = self.failures.numel()
        fail = self.failures.clone()
        # half of a bin's failures also pull starts into the bin before it, same reference
        same = self._bin_clip[1:] == self._bin_clip[:-1]
        fail[:-1] += 0.5 * self.failures[1:] * same
        total = float(fail.sum())
        uniform = torch.full_like(fail, 1.0 / num_bins)
        if total <= 0:
            return uniform
        share = self.cfg.uniform_share
        return share * uniform + (1 - share) * fail / total

    def _sample(self, env_ids: torch.Tensor) -> None:
        lib, m, dev = self.library, env_ids.numel(), self.device
        if self.evaluation:
            clip = env_ids % len(lib.names)
            self.clip[env_ids] = clip
            self.start_frame[env_ids] = self._start[clip]
            self.steps[env_ids] = 0
            return
        bins = torch.multinomial(
            self.sampling_probabilities().float(), m, replacement=True, generator=self.generator
        )
        clip = self._bin_clip[bins]
        offset = (torch.rand(m, generator=self.generator, device=dev) * self._bin_frames).long()
        frame = self._bin_start[bins] + offset
        last_start = self._start[clip] + (self._length[clip] - self.cfg.min_frames_left).clamp_min(
            0
        )
        self.clip[env_ids] = clip
        self.start_frame[env_ids] = torch.minimum(frame, last_start)
        self.steps[env_ids] = 0

    def reset_state(self, env_ids, qpos, qvel, generator) -> None:
        """Note where the ending episodes were (for the failure counts), then put the robots on
        their new start frames (:meth:`ClipTrackingCommand.reset_state`)."""
        self._ended_bin[env_ids] = self._bin_of(self.frame(0)[env_ids])
        self._ended[env_ids] = True
        super().reset_state(env_ids, qpos, qvel, generator)

    def for_evaluation(self) -> None:
        """Each env tracks reference ``env id mod K`` from its first frame."""
        self.evaluation = True

    # ------------------------------------------------------------------------------ each step
    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Count the failures of the episodes that just ended, advance the reference by one step
        (not for envs reset this step) and return the command targeting the next frame (N, 67)."""
        if abs(state.step_dt_s - self.cfg.step_dt_s) > 1e-9:
            raise ValueError(
                f"references are sampled at step_dt_s = {self.cfg.step_dt_s} s but the env steps "
                f"{state.step_dt_s} s: set the task's commands.step_dt_s to the env's step"
            )
        if not self.evaluation and state.body_pos_w is not None:
            failed = self._ended & state.terminated
            counts = torch.zeros_like(self.failures)
            counts.index_add_(
                0,
                self._ended_bin[failed],
                torch.ones_like(self._ended_bin[failed], dtype=counts.dtype),
            )
            alpha = self.cfg.failure_ema
            self.failures.mul_(1 - alpha).add_(alpha * counts)
        self._ended[:] = False
        if self.cfg.oracle and not self.evaluation and state.applied_wrench is not None:
            live = ~self.fresh  # a fresh env's wrench was its last episode's
            force = state.applied_wrench[live, :3].double().norm(dim=-1)
            bins = self._bin_of(self.frame(0)[live])
            self._bin_help[0].index_add_(0, bins, force)
            self._bin_help[1].index_add_(0, bins, torch.ones_like(force))
        if self._targets and (~self.fresh).any():
            err = (state.joint_pos_rad - self._targets["joint_pos_rad"]).abs().mean(-1)[~self.fresh]
            self._error_sum += float(err.sum())
            self._error_count += int(err.numel())
        self.steps += (~self.fresh).long()
        self.fresh[:] = False
        nxt = self.frame(ahead=1)
        targets = {k: v[nxt] for k, v in self._bodies.items()}
        targets["body_pos_w"] = targets["body_pos_w"].clone()
        targets["body_pos_w"][..., 2] += self.z_offset_m.float().unsqueeze(-1)
        targets["joint_pos_rad"] = self._joint[nxt, : g1.NUM_JOINTS]
        targets["phase"] = self._phase[nxt]
        self._targets = targets
        anchor = anchor_command(
            state.body_pos_w[:, ANCHOR],
            state.body_quat_w[:, ANCHOR],
            targets["body_pos_w"][:, ANCHOR],
            targets["body_quat_w"][:, ANCHOR],
        )
        return torch.cat([self._joint[nxt], anchor], dim=-1)

    def bin_names(self) -> list[str]:
        """Each adaptive-sampling bin's name: its start along its reference, ``t3s`` (``1:t3s``
        for the second reference where there are several)."""
        local = (self._bin_start - self._start[self._bin_clip]).tolist()
        clips = self._bin_clip.tolist()
        several = len(self.library.names) > 1
        return [
            f"{k}:" * several + f"t{f * self.cfg.step_dt_s:g}s"
            for k, f in zip(clips, local, strict=True)
        ]

    def log(self) -> dict[str, float]:
        """The joint tracking error; with an oracle also, per bin, the mean applied help force
        [N] since the last log and the bin's share of the failures (the adaptive sampler's
        moving counts): where the clip is helped beside where episodes fail."""
        out = super().log()
        if not self.cfg.oracle or self.evaluation:
            return out
        names = self.bin_names()
        total = float(self.failures.sum())
        share = (self.failures / total if total > 0 else self.failures).tolist()
        sums, counts = self._bin_help.tolist()
        for k, name in enumerate(names):
            if counts[k] > 0:
                out[f"Oracle/help_force_n/{name}"] = sums[k] / counts[k]
            out[f"Oracle/failure_share/{name}"] = share[k]
        self._bin_help.zero_()
        return out

    def targets(self) -> dict[str, torch.Tensor]:
        """The next frame's tracked-link poses and velocities (N, K, 3|4) and joints (N, 29)."""
        return self._targets

    def time_outs(self) -> torch.Tensor:
        """Episodes whose robot just reached its reference's last frame (called in the step,
        before the command advances: this step's target was the frame one ahead)."""
        return self.frame(ahead=2) == self.frame(ahead=1)

    def columns(self) -> tuple[CommandColumns, ...]:
        """The reference frame after this step: joints, joint rates, anchor seen from the robot."""
        frame = (
            "of the reference frame the robot should reach after this policy step (references at "
            f"the policy rate, one frame per step; references: {', '.join(self.cfg.sources)})"
        )
        return (
            CommandColumns("joint_pos_ref", g1.NUM_JOINTS, "rad",
                           f"joint angles (absolute; order of `joints`) {frame}"),
            CommandColumns("joint_vel_ref", g1.NUM_JOINTS, "rad/s", f"joint rates {frame}"),
            CommandColumns(
                "anchor_pos_b", 3, "m",
                f"position of the reference's torso_link {frame}, in the robot's torso_link frame",
                from_robot=True,
            ),
            CommandColumns(
                "anchor_rot_b", 6, "-",
                "orientation of the reference's torso_link relative to the robot's: first two "
                f"columns of the rotation matrix, column-major {frame}",
                from_robot=True,
            ),
        )  # fmt: skip

    def reference_time_s(self) -> torch.Tensor:
        """Per env, the time of its current frame along its reference as loaded (N,) [s]: the
        held frames before it come first, at negative times (an artifact's coach follows it)."""
        return super().reference_time_s() - self.motion.hold_frames * self.cfg.step_dt_s

    def reference_joint_pos_rad(self) -> torch.Tensor:
        """Joint pose (N, 29) [rad] of each env's next frame (the command's joint targets)."""
        return self._joint[self.frame(ahead=1), : g1.NUM_JOINTS].clone()

    def reference_link_contact(self, names: tuple[str, ...], margin_frames: int) -> torch.Tensor:
        """(N, len(names)) bool: the link ``names[b]`` (not a sole) of each env's reference is on
        the ground within ``margin_frames`` of its current frame (a flip's crouching shins)."""
        if self._link_contact is None or self._link_contact[0] != margin_frames:
            down = self.motion.link_ground_contact.float()[None, None]  # (1, 1, F, B)
            k = 2 * margin_frames + 1
            near = torch.nn.functional.max_pool2d(
                down, (k, 1), stride=1, padding=(margin_frames, 0)
            )[0, 0]
            self._link_contact = (margin_frames, near.bool().to(self.device))
        cols = [self.motion.contact_bodies.index(b) for b in names]
        return self._link_contact[1][self.frame()][:, cols]

    def deployment_reference(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The whole motion library as a bundle carries it (:mod:`rl.tasks.track.bundle_reference`)."""
        from rl.tasks.track.bundle_reference import reference_for_bundle

        return reference_for_bundle(self)

    def reference_joint_feedforward(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Joint rates (N, 29) [rad/s] and planned joint torques (N, 29) [N m] of each env's next
        frame (0 torque where the reference has none: a clip)."""
        nxt = self.frame(ahead=1)  # indexing by a tensor copies: no clone needed
        return self._joint[nxt, g1.NUM_JOINTS :], self._torque[nxt]

    def state_dict(self) -> dict[str, Any]:
        """Per-env references and frames, the failure counts and the last targets."""
        return {
            **super().state_dict(),
            "failures": self.failures.clone(),
            "ended": self._ended.clone(),
            "ended_bin": self._ended_bin.clone(),
            "targets": {k: v.clone() for k, v in self._targets.items()},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (onto this command's device)."""
        state = dict(state)
        self._targets = {k: v.to(self.device, copy=True) for k, v in state.pop("targets").items()}
        self.failures = state.pop("failures").to(self.device, copy=True)
        self._ended = state.pop("ended").to(self.device, copy=True)
        self._ended_bin = state.pop("ended_bin").to(self.device, copy=True)
        super().load_state_dict(state)


def bin_table(command: MotionCommand) -> np.ndarray:
    """Per bin: (reference index, first local frame, failures, start probability) (B, 4)."""
    local = command._bin_start - command._start[command._bin_clip]
    return np.stack(
        [
            command._bin_clip.cpu().numpy(),
            local.cpu().numpy(),
            command.failures.cpu().numpy(),
            command.sampling_probabilities().cpu().numpy(),
        ],
        axis=1,
    )


__all__ = ["TRACKED_BODIES", "MotionCommand", "MotionCommandConfig", "bin_table"]
