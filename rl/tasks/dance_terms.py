"""The dance's clip library, tracking command, tracking reward terms and skill measure.

Command (paper, "Dancing"): ``c_t = [dp_cmd (3), dq_cmd (4), q_cmd (29)]`` (width 36), the
reference's step for the *next* policy step: its base displacement over one step ``dt`` in its own
heading (yaw) frame, its base rotation over the step as a unit quaternion ``exp(w_b dt / 2)``
(w x y z, body frame), and its joint angles. The robot's own ``dp`` and ``dq`` are computed by the
same functions from its state (pelvis velocity x ``dt`` in its heading frame, pelvis rotation over
``dt``), so a robot put exactly on the reference frame has exactly zero tracking error.

Clips come from :mod:`optimal_control` loaders: ``"builtin"`` is the built-in choreography
(:func:`optimal_control.dance.built_in_dance`, cached on disk after its first IK solve), any other
source a CSV / NPZ clip path (:func:`optimal_control.motion_clip.load_motion_clip`, resampled to
50 Hz). Each episode tracks one clip, drawn uniformly, from a start frame drawn uniformly along it
(no emphasis on hard segments); past the clip's end the last frame is held.
"""

from __future__ import annotations

import hashlib
import inspect
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from optimal_control.files import atomic_save_npz
from rl.envs.state import EnvState, quat_multiply
from rl.tasks.components import Command, CommandColumns, EpisodeWindow, SkillMeasure
from robots import g1

BUILTIN_CLIP = "builtin"
"""Clip source name of the built-in choreography."""
COMMAND_DIM = 3 + 4 + g1.NUM_JOINTS
"""Width of the dance command [dp (3), dq (4), q (29)]."""
BODY_PARTS = g1.BODY_PARTS
"""Joint index ranges of the body parts (``robots.g1.JOINTS`` order)."""


# --------------------------------------------------------------------------- step features
def yaw_of(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """Heading (yaw about world z) of unit quaternions (N, 4) w x y z, shape (N,) [rad]."""
    w, x, y, z = quat_wxyz.unbind(-1)
    return torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def step_displacement(
    quat_wxyz: torch.Tensor, lin_vel_w: torch.Tensor, dt_s: float
) -> torch.Tensor:
    """Base displacement over one step ``dt_s`` [s] in the heading frame, (N, 3) [m]."""
    yaw = yaw_of(quat_wxyz)
    c, s = torch.cos(yaw), torch.sin(yaw)
    d = lin_vel_w * dt_s
    return torch.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], dim=-1)


def step_rotation(ang_vel_b: torch.Tensor, dt_s: float) -> torch.Tensor:
    """Base rotation over one step as a unit quaternion exp(w dt / 2), (N, 4) w x y z [-]."""
    rot = ang_vel_b * dt_s
    angle = rot.norm(dim=-1, keepdim=True)
    half = angle / 2
    # sin(a/2)/a with its limit 1/2 at a = 0 (no division by zero)
    scale = torch.where(angle > 1e-8, torch.sin(half) / angle.clamp_min(1e-8), 0.5 - angle**2 / 48)
    return torch.cat([torch.cos(half), rot * scale], dim=-1)


def _split(command: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    return command[:, :3], command[:, 3:7], command[:, 7:]


# ------------------------------------------------------------------------------- reward terms
def base_displacement_error_sq(s: EnvState) -> torch.Tensor:
    """``|dp - dp_cmd|^2`` (N,) [m^2]."""
    dp = step_displacement(s.base_quat_w, s.base_lin_vel_w, s.step_dt_s)
    return (dp - _split(s.command)[0]).square().sum(-1)


def base_rotation_error_sq(s: EnvState) -> torch.Tensor:
    """``|dq - dq_cmd|^2`` of the step quaternions (N,) [-]."""
    dq = step_rotation(s.base_ang_vel_b, s.step_dt_s)
    return (dq - _split(s.command)[1]).square().sum(-1)


def joint_error_sq(s: EnvState) -> torch.Tensor:
    """``|q - q_cmd|^2`` summed over the 29 joints (N,) [rad^2]."""
    return (s.joint_pos_rad - _split(s.command)[2]).square().sum(-1)


def joint_error_mean_abs(s: EnvState) -> torch.Tensor:
    """Mean absolute joint tracking error over the 29 joints (N,) [rad] (the skill's error)."""
    return (s.joint_pos_rad - _split(s.command)[2]).abs().mean(-1)


def track_base_position(s: EnvState, scale: float = 2500.0) -> torch.Tensor:
    """``exp(-scale |dp - dp_cmd|^2)`` (N,) [-] (``scale`` [1/m^2])."""
    return torch.exp(-scale * base_displacement_error_sq(s))


def track_base_rotation(s: EnvState, scale: float = 100.0) -> torch.Tensor:
    """``exp(-scale |dq - dq_cmd|^2)`` (N,) [-]."""
    return torch.exp(-scale * base_rotation_error_sq(s))


def track_joint_position(s: EnvState, scale: float = 0.25) -> torch.Tensor:
    """``exp(-scale |q - q_cmd|^2)`` (N,) [-] (``scale`` [1/rad^2])."""
    return torch.exp(-scale * joint_error_sq(s))


def track_joint_rms(s: EnvState, std_rad: float = 0.2) -> torch.Tensor:
    """``exp(-(rms / std)^2)`` of the RMS joint error over the 29 joints (N,) [-].

    Steep around the skill target: with ``std_rad`` 0.2 (an RMS of 0.2 rad is a mean absolute error
    of about 0.16 rad, the target) it pays 0.61 at 0.14 rad RMS, 0.37 at 0.2 and 0.04 at 0.36,
    where the paper's ``exp(-0.25 |e|^2)`` pays 0.87, 0.75 and 0.39 (it acts as an alive bonus).
    """
    mean_sq = joint_error_sq(s) / s.joint_pos_rad.shape[-1]
    return torch.exp(-mean_sq / std_rad**2)


# -------------------------------------------------------------------------------- clip library
def _cache_dir() -> Path:
    return Path.home() / ".cache" / "a2cf-mb" / "dance"


def _builtin_reference():
    """The built-in dance reference; its IK solve (~3 s CPU + placo import) is cached on disk,
    keyed by the dance config and the source of :mod:`optimal_control.dance`."""
    from optimal_control import dance
    from optimal_control.reference import Reference

    key = hashlib.sha256(
        (repr(asdict(dance.DanceConfig())) + inspect.getsource(dance)).encode()
    ).hexdigest()[:16]
    path = _cache_dir() / f"builtin_{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as data:
                arrays = {k: data[k] for k in data.files}
            return Reference.from_arrays(arrays, dance.DANCE_PHASES, "dance")
        except (OSError, ValueError, KeyError):
            path.unlink(missing_ok=True)  # a broken cache file is rebuilt
    ref = dance.built_in_dance().reference
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_save_npz(path, ref.to_arrays(), compressed=False)
    return ref


def load_reference(source: str):
    """The :class:`optimal_control.reference.Reference` of one clip source."""
    if source == BUILTIN_CLIP:
        return _builtin_reference()
    from optimal_control.motion_clip import load_motion_clip

    if not Path(source).is_file():
        raise FileNotFoundError(
            f"dance clip '{source}' not found: pass a CSV/NPZ clip path or '{BUILTIN_CLIP}'"
        )
    return load_motion_clip(source, name=Path(source).stem)


@dataclass
class ClipLibrary:
    """All frames of the task's clips, concatenated (F frames in total).

    ``qpos``/``qvel`` are MuJoCo-layout float64 (F, 36) / (F, 35); ``floor_shift_m`` (F,) is how
    far each frame must be lowered so that its lowest sole corner sits where the standing
    keyframe's does (positive: the retargeted feet hover; negative: they sink). ``command`` (F, 36)
    float32 is the command targeting each frame. ``start`` / ``length`` (K,) locate each clip.
    """

    names: tuple[str, ...]
    qpos: np.ndarray
    qvel: np.ndarray
    floor_shift_m: np.ndarray
    command: torch.Tensor
    start: torch.Tensor
    length: torch.Tensor
    dt_s: float

    @classmethod
    def load(cls, sources: tuple[str, ...], step_dt_s: float) -> ClipLibrary:
        """Load every source; all clips must have the policy step ``step_dt_s`` [s] as frame step."""
        from optimal_control.motion_clip import sole_corner_heights_m
        from robots.conventions import pin_to_mj_qpos, pin_to_mj_qvel
        from robots.pinocchio_model import build_pinocchio_model

        if not sources:
            raise ValueError("the dance task needs at least one clip source")
        robot = build_pinocchio_model()
        stand_floor = sole_corner_heights_m(robot.q_stand[None], robot)[0].min()
        qpos, qvel, shift, starts, lengths = [], [], [], [], []
        for source in sources:
            ref = load_reference(source)
            if abs(ref.dt - step_dt_s) > 1e-9:
                raise ValueError(
                    f"dance clip '{source}' has frame step {ref.dt} s, the policy step is "
                    f"{step_dt_s} s: resample the clip to {1 / step_dt_s:g} fps"
                )
            heights, _ = sole_corner_heights_m(ref.q, robot)
            starts.append(sum(lengths))
            lengths.append(ref.q.shape[0])
            qpos.append(pin_to_mj_qpos(ref.q))
            qvel.append(pin_to_mj_qvel(ref.q, ref.v))
            shift.append(heights.min(axis=1) - stand_floor)
        qpos_all, qvel_all = np.concatenate(qpos), np.concatenate(qvel)
        return cls(
            names=tuple(sources),
            qpos=qpos_all,
            qvel=qvel_all,
            floor_shift_m=np.concatenate(shift),
            command=frame_commands(qpos_all, qvel_all, step_dt_s),
            start=torch.tensor(starts),
            length=torch.tensor(lengths),
            dt_s=step_dt_s,
        )


def frame_commands(qpos: np.ndarray, qvel: np.ndarray, dt_s: float) -> torch.Tensor:
    """The command (F, 36) float32 that targets each frame of MuJoCo ``qpos`` / ``qvel`` rows."""
    q = torch.as_tensor(qpos).float()
    v = torch.as_tensor(qvel).float()
    return torch.cat(
        [step_displacement(q[:, 3:7], v[:, :3], dt_s), step_rotation(v[:, 3:6], dt_s), q[:, 7:]],
        dim=-1,
    )


_LIBRARIES: dict[tuple[tuple[str, ...], float], ClipLibrary] = {}


def clip_library(sources: tuple[str, ...], step_dt_s: float) -> ClipLibrary:
    """The (per-process cached) library of ``sources``."""
    key = (tuple(sources), float(step_dt_s))
    if key not in _LIBRARIES:
        _LIBRARIES[key] = ClipLibrary.load(key[0], step_dt_s)
    return _LIBRARIES[key]


# ------------------------------------------------------------------------------------ command
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

    def __init__(self, cfg: ClipTrackingConfig, num_envs: int, generator: torch.Generator) -> None:
        self.cfg = cfg
        self.generator = generator
        self.library = clip_library(cfg.sources, cfg.step_dt_s)
        self.clip = torch.zeros(num_envs, dtype=torch.long)
        self.start_frame = torch.zeros(num_envs, dtype=torch.long)  # global frame index
        self.steps = torch.zeros(num_envs, dtype=torch.long)
        self.z_offset_m = torch.zeros(num_envs, dtype=torch.float64)
        self.fresh = torch.ones(num_envs, dtype=torch.bool)
        self._error_sum = 0.0
        self._error_count = 0

    def _sample(self, env_ids: torch.Tensor) -> None:
        lib, m = self.library, env_ids.numel()
        clip = torch.randint(len(lib.names), (m,), generator=self.generator)
        length = lib.length[clip]
        span = (length - self.cfg.min_frames_left).clamp_min(1)
        offset = (torch.rand(m, generator=self.generator) * span).long()
        self.clip[env_ids] = clip
        self.start_frame[env_ids] = lib.start[clip] + offset
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
        frames = self.start_frame[env_ids].numpy()
        lib = self.library
        rows = torch.as_tensor(lib.qpos[frames]).clone()
        shift = torch.as_tensor(lib.floor_shift_m[frames])
        rows[:, 2] -= shift
        self.z_offset_m[env_ids] = -shift
        qpos[:] = rows
        qvel[:] = torch.as_tensor(lib.qvel[frames])

    def reset(self, env_ids: torch.Tensor) -> None:
        """The next :meth:`compute` keeps these envs on their start frame."""
        self.fresh[env_ids] = True

    def frame(self, ahead: int = 0) -> torch.Tensor:
        """Global frame index (N,) of each env's reference ``ahead`` steps on (held at the end)."""
        local = self.start_frame - self.library.start[self.clip] + self.steps + ahead
        return self.library.start[self.clip] + local.clamp_max(self.library.length[self.clip] - 1)

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
        command = self.library.command[nxt].clone()
        at_end = nxt == self.frame(ahead=0)
        command[at_end, :3] = 0.0
        command[at_end, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0])
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
        return (self.frame(0) - self.library.start[self.clip]).double() * self.library.dt_s

    def reference_joint_pos_rad(self) -> torch.Tensor:
        """Joint pose (N, 29) [rad] of each env's next frame (the command's joint targets)."""
        return torch.as_tensor(self.library.qpos[self.frame(ahead=1).numpy(), 7:]).float()

    def reference_pose(self, ahead: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
        """Reference pelvis position (N, 3) [m] (with each env's floor offset) and orientation
        (N, 4) w x y z of the frame ``ahead`` steps on."""
        frames = self.frame(ahead).numpy()
        qpos = torch.as_tensor(self.library.qpos[frames]).clone()
        qpos[:, 2] += self.z_offset_m
        return qpos[:, :3].float(), qpos[:, 3:7].float()

    def log(self) -> dict[str, float]:
        """Mean absolute joint tracking error of the steps since the last log [rad]."""
        if not self._error_count:
            return {}
        out = {"Dance/joint_error_rad": self._error_sum / self._error_count}
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
        """Restore the per-env buffers."""
        for key, value in state.items():
            setattr(self, key, value.clone())


# ------------------------------------------------------------------------------- skill measure
@dataclass(frozen=True)
class TrackingSkillConfig:
    """Skill = ``threshold_rad`` over the mean joint tracking error of recent episodes.

    Each counted episode contributes its mean absolute joint error at its last step (the
    :class:`SkillMeasure` hook sees the episode's last state only), a fall ``fall_error_rad``.
    """

    threshold_rad: float = 0.16  # joint tracking error that counts as learned (paper) [rad]
    fall_error_rad: float = 1.0  # error charged for an episode that fell [rad]
    window: int = 256  # counted episodes in the moving window [-]

    def __post_init__(self) -> None:
        if self.threshold_rad <= 0 or self.window < 1:
            raise ValueError(f"need threshold_rad > 0 and window >= 1, got {self}")

    def build(self, max_episode_length: int) -> SkillMeasure:
        """The live measure."""
        return TrackingSkill(self, max_episode_length)


class TrackingSkill(SkillMeasure):
    """Moving window of episode tracking errors (see :class:`TrackingSkillConfig`)."""

    def __init__(self, cfg: TrackingSkillConfig, max_episode_length: int) -> None:
        self.cfg = cfg
        self.max_episode_length = max_episode_length
        self.window = EpisodeWindow(cfg.window)

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Push the error of each counted finished episode."""
        err = joint_error_mean_abs(state)[env_ids]
        err = torch.where(time_outs, err, torch.full_like(err, self.cfg.fall_error_rad))
        self.window.push(err[self.counted(time_outs, lived_steps)])

    def mean_error_rad(self) -> float:
        """Mean error of the window [rad] (inf before any counted episode)."""
        return self.window.mean(empty=math.inf)

    def progress(self) -> float:
        """``threshold / mean error`` (>= 1: learned; 0 before any episode)."""
        err = self.mean_error_rad()
        return self.cfg.threshold_rad / err if math.isfinite(err) and err > 0 else 0.0

    def log(self) -> dict[str, float]:
        """The window's mean episode-end joint error."""
        return {"Skill/dance_joint_error_rad": self.mean_error_rad()} if self.window.count else {}

    def state_dict(self) -> dict[str, Any]:
        """The window."""
        return self.window.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the window."""
        self.window.load_state_dict(state)


def quat_angle(a_wxyz: torch.Tensor, b_wxyz: torch.Tensor) -> torch.Tensor:
    """Rotation angle between orientations (N, 4) w x y z, shape (N,) [rad]."""
    conj = b_wxyz * torch.tensor([1.0, -1.0, -1.0, -1.0])
    rel = quat_multiply(conj, a_wxyz)
    return 2 * torch.atan2(rel[:, 1:].norm(dim=-1), rel[:, 0].abs())
