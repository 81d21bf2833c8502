"""Tracking a flip (a ``solve-backflip`` artifact, a mocap backflip): how the tracking task is set
up for it and how a flip is judged, on top of the tracking errors.

A reference *flips* when its pelvis turns by more than pi about its own pitch axis
(:func:`rl.tasks.track.library.pitch_turn_rad`). :func:`for_flips` then holds its ends for
``hold_s`` (the robot starts and ends standing), reads its phases from the reference (an
artifact's stand, crouch, jump, air, land: eta0 and the curriculum work per phase) and judges
it with :class:`FlipEvaluator`. Training still starts episodes along the whole flip (reference
state initialisation with adaptive sampling); an evaluation always starts on the first, standing
frame.

A flip is *landed* when, in one episode from standing:

* the pelvis turned at least ``min_turn_rad`` (2 pi - 0.5) in the reference's direction;
* the soles touched down after that turn, and no other link touched the ground at any step
  where the reference keeps it off (within ``contact_margin_s``: the oracle's deep crouch puts
  the shins' collision geometry on the floor, and tracking it is no fall);
* the episode reached the reference's end without a fall or a drift termination, and the robot
  was upright (pelvis tilt <= ``max_tilt_rad``) and still (pelvis speed <= ``max_speed_mps``,
  angular speed <= ``max_ang_speed_rps``) over its last ``still_s``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import torch

from rl.tasks.terminations import base_tilted
from rl.tasks.track.evaluation import TrackEvaluationConfig, TrackEvaluator
from rl.tasks.track.library import pitch_increment_rad

FLIP_HOLD_S = 1.5
"""Seconds a flip reference's first and last frames are held: the robot starts standing, and
has half a second to settle before the last second, over which it must stand still."""


@dataclass(frozen=True)
class FlipEvaluationConfig(TrackEvaluationConfig):
    """The tracking evaluation plus what makes a flip landed (see the module docstring)."""

    direction: float = -1.0  # sign of the reference's pitch turn (-1: a backflip) [-]
    min_turn_rad: float = 2 * math.pi - 0.5  # pelvis pitch turn that counts as a full flip [rad]
    contact_threshold_n: float = 20.0  # a sole carrying more is on the ground [N]
    still_s: float = 1.0  # the episode's last seconds the robot must stand still [s]
    max_tilt_rad: float = 0.35  # upright: pelvis up axis within this of vertical [rad]
    max_speed_mps: float = 0.3  # still: pelvis speed at most this [m/s]
    max_ang_speed_rps: float = 1.0  # still: pelvis angular speed at most this [rad/s]
    # a link may touch the ground where the reference's does, this close in time [s]
    contact_margin_s: float = 0.1

    def build(self, env: Any) -> FlipEvaluator:
        """The evaluator of one rollout on ``env`` (a flip-tracking task's env)."""
        return FlipEvaluator(self, env)


class FlipEvaluator(TrackEvaluator):
    """The tracking errors (:class:`TrackEvaluator`) and, per env's first episode, the pitch
    turned (summed over the pelvis's orientation from step to step), the furthest phase reached, touch-down after the turn, other links' ground contacts
    and the steps it has stood still, upright, at the end."""

    def __init__(self, cfg: FlipEvaluationConfig, env: Any) -> None:
        super().__init__(cfg, env)
        n = env.num_envs
        self.turned = torch.zeros(n, dtype=torch.float64)
        self.max_phase = torch.zeros(n, dtype=torch.long)
        self.landed = torch.zeros(n, dtype=torch.bool)
        self.other_contact = torch.zeros(n, dtype=torch.bool)
        self.still_steps = torch.zeros(n, dtype=torch.long)
        self.finished = torch.zeros(n, dtype=torch.bool)  # reached the reference's end
        self._last_quat = env.env_state.base_quat_w.cpu().clone()  # the pelvis a step ago

    def on_step(self, env: Any, active: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Accumulate the flip's record of the envs still in their first episode (a reset env's
        state belongs to its next episode and is not read)."""
        cfg: FlipEvaluationConfig = self.cfg  # type: ignore[assignment]
        s = env.env_state.to("cpu")
        done = dones.bool().cpu()
        time_out = extras["time_outs"].bool().cpu()
        self.finished |= active & done & time_out
        keep = active & ~done
        if keep.any():
            turn = pitch_increment_rad(self._last_quat.double(), s.base_quat_w.double())
            self.turned += torch.where(keep, cfg.direction * turn, 0.0)
            self.max_phase = torch.where(
                keep, torch.maximum(self.max_phase, env.phase.cpu()), self.max_phase
            )
            turned = self.turned >= cfg.min_turn_rad
            soles = (s.foot_contact_force_n > cfg.contact_threshold_n).all(dim=-1)
            self.landed |= keep & turned & soles
            # a link on the ground where the reference keeps it off (its crouching shins are not)
            ref_down = env.command_gen.reference_link_contact(
                s.contact_body_names, round(cfg.contact_margin_s / env.step_dt_s)
            ).cpu()
            self.other_contact |= keep & (s.body_ground_contact & ~ref_down).any(dim=-1)
            still = (
                ~base_tilted(s, cfg.max_tilt_rad)
                & (s.base_lin_vel_w.norm(dim=-1) <= cfg.max_speed_mps)
                & (s.base_ang_vel_b.norm(dim=-1) <= cfg.max_ang_speed_rps)
            )
            self.still_steps = torch.where(
                keep, torch.where(still, self.still_steps + 1, 0), self.still_steps
            )
        self._last_quat = s.base_quat_w.clone()
        super().on_step(env, active, dones, extras)

    def stood_still(self) -> torch.Tensor:
        """(N,) bool: upright and still over the episode's last ``still_s`` (the last frame, a
        time-out's, is not scored: one step fewer)."""
        return self.still_steps >= max(1, round(self.cfg.still_s / self._env.step_dt_s) - 1)

    def flipped(self) -> torch.Tensor:
        """(N,) bool: the env's first episode landed its flip (module docstring)."""
        cfg: FlipEvaluationConfig = self.cfg  # type: ignore[assignment]
        return (
            self.finished
            & ~self.fell
            & (self.turned >= cfg.min_turn_rad)
            & self.landed
            & ~self.other_contact
            & self.stood_still()
        )

    def _summary(self, envs: torch.Tensor) -> dict[str, Any]:
        out = super()._summary(envs)
        landed = self.flipped()[envs].float()
        names = self._env.task.phase_names
        reached = self.max_phase[envs]
        out.update(
            flips_landed=float(landed.mean()),
            flips_failed=float(1.0 - landed.mean()),
            turn_rad_mean=float(self.turned[envs].mean()),
            turn_rad_max=float(self.turned[envs].max()),
            full_turns=float((self.turned[envs] >= self.cfg.min_turn_rad).float().mean()),
            touched_down_after_turn=float(self.landed[envs].float().mean()),
            other_link_on_ground=float(self.other_contact[envs].float().mean()),
            upright_still_at_end=float(self.stood_still()[envs].float().mean()),
            phase_reached={
                name: float((reached == p).float().mean()) for p, name in enumerate(names)
            },
        )
        return out


def for_flips(task: Any, refs: list, turn_rad: float) -> Any:
    """``task`` (a tracking task) set up for flip references ``refs`` that turn ``turn_rad``
    [rad]: ends held :data:`FLIP_HOLD_S`, the episode long enough for the whole reference, the
    flip evaluation and a target of half the flips landed from standing."""
    from rl.envs.task_schema import SkillTarget

    duration = max(r.duration_s for r in refs) + 2 * FLIP_HOLD_S
    return dataclasses.replace(
        task,
        commands=dataclasses.replace(task.commands, hold_s=FLIP_HOLD_S),
        episode_length_s=max(task.episode_length_s, math.ceil(duration + 1.0)),
        evaluation=FlipEvaluationConfig(direction=math.copysign(1.0, turn_rad)),
        target=SkillTarget(min_survival=0.0, metric="flips_failed", max_metric=0.5),
    )
