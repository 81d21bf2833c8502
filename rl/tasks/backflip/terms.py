"""The backflip's phase-masked terms and its stateful parts (start command, phase FSM, success).

Phases (paper, "Backflip", after kim2024stage): 0 Stand, 1 Crouch, 2 Jump, 3 Air, 4 Land. The FSM
(:class:`BackflipPhaseMachine`) moves one phase forward per step at most:

- Stand -> Crouch: the start command ``c_t = 1_start`` is on (:class:`StartCommand`);
- Crouch -> Jump: the pelvis is below ``crouch_height_m``;
- Jump -> Air: neither sole touches the ground;
- Air -> Land: a sole touches the ground *and* the pitch turned since the crouch is at least
  ``min_turn_rad`` (a half turn): a touch-down before that is no landing (the env stays in Air,
  the episode is flagged ``landed_short`` and can no longer succeed).

The pitch turned is the integral of ``-w_y`` (pelvis frame, backward positive) from the crouch on.
Reward terms are pure functions of :class:`rl.envs.state.EnvState` returning (N,); phase masks
read ``state.phase`` (the phase in which the step's action was applied).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import torch

from rl.envs.components import (
    Command,
    CommandColumns,
    PhaseMachine,
    SkillMeasure,
    WindowedSkill,
)
from rl.envs.state import EnvState, quat_rotate
from robots import g1

BACKFLIP_PHASES = ("stand", "crouch", "jump", "air", "land")
"""Phase names, in FSM order (one assist-bound row each)."""
STAND, CROUCH, JUMP, AIR, LAND = range(5)

BUILTIN_POSES = "builtin"
"""``source`` of :func:`desired_joint_poses` for the built-in per-phase poses."""

# Built-in desired joint poses per phase [rad] (joint name -> angle; others: stand pose). Sign
# conventions of the G1: hip pitch < 0 flexes the hip, knee > 0 flexes the knee, shoulder pitch < 0
# raises the arm forward/up.
_LEGS = ("left", "right")
_BUILTIN_OFFSETS: tuple[dict[str, float], ...] = (
    {},  # stand: the stand pose
    {"hip_pitch": -1.0, "knee": 1.6, "ankle_pitch": -0.6, "shoulder_pitch": 0.8, "elbow": 0.3},
    {"hip_pitch": -0.2, "knee": 0.2, "ankle_pitch": 0.2, "shoulder_pitch": -2.5, "elbow": 0.2},
    {"hip_pitch": -1.8, "knee": 2.0, "ankle_pitch": -0.3, "shoulder_pitch": -1.2, "elbow": 1.0},
    {"hip_pitch": -0.6, "knee": 1.1, "ankle_pitch": -0.5, "shoulder_pitch": 0.2, "elbow": 0.6},
)


def builtin_joint_poses() -> np.ndarray:
    """The built-in desired joint pose of each phase (5, 29) [rad], inside the joint limits."""
    poses = np.tile(g1.STAND_JOINT_POS_RAD, (len(BACKFLIP_PHASES), 1))
    for phase, offsets in enumerate(_BUILTIN_OFFSETS):
        for joint, angle in offsets.items():
            for side in _LEGS:
                poses[phase, g1.JOINT_NAMES.index(f"{side}_{joint}_joint")] = angle
    return poses


@lru_cache(maxsize=8)
def _poses_from_artifact(folder: str) -> tuple[tuple[float, ...], ...]:
    from optimal_control.artifact import OracleArtifact

    art = OracleArtifact.load(folder)
    if art.phase_names != BACKFLIP_PHASES:
        raise ValueError(
            f"oracle artifact '{folder}' has phases {art.phase_names}, not the backflip's "
            f"{BACKFLIP_PHASES}: pass a `a2cf-mb solve-backflip` artifact"
        )
    ref = art.reference
    joints = np.asarray(ref.q)[:, 7:]  # Pinocchio q: base xyz, quaternion xyzw, 29 joints
    rows = []
    for phase, name in enumerate(BACKFLIP_PHASES):
        frames = np.asarray(ref.phase) == phase
        if not frames.any():
            raise ValueError(f"oracle artifact '{folder}' has no frame in phase '{name}'")
        rows.append(tuple(float(v) for v in joints[frames].mean(axis=0)))
    return tuple(rows)


def desired_joint_poses(source: str = BUILTIN_POSES) -> torch.Tensor:
    """Desired joint pose per phase (5, 29) [rad] from ``source``: ``"builtin"``, or the folder of
    a backflip oracle artifact, whose reference gives the mean joint pose over each phase's
    frames (the trajectory optimisation's pose per phase). Loaded once per source."""
    if source == BUILTIN_POSES:
        return torch.as_tensor(builtin_joint_poses(), dtype=torch.float32)
    return torch.tensor(_poses_from_artifact(str(source)), dtype=torch.float32)


_POSE_CACHE: dict[tuple[str, torch.device], torch.Tensor] = {}


def _poses(source: str, device: torch.device) -> torch.Tensor:
    """The poses of ``source`` on ``device`` (loaded, and copied there, once per process)."""
    key = (source, device)
    if key not in _POSE_CACHE:
        _POSE_CACHE[key] = desired_joint_poses(source).to(device)
    return _POSE_CACHE[key]


# ------------------------------------------------------------------------------- reward terms
def in_phases(s: EnvState, phases: tuple[int, ...]) -> torch.Tensor:
    """1 where the env's phase is one of ``phases``, else 0 (N,) [-]."""
    mask = torch.zeros_like(s.phase, dtype=torch.bool)
    for p in phases:
        mask |= s.phase == p
    return mask.to(torch.float32)


def phase_alive(s: EnvState, phases: tuple[int, ...] = (STAND,)) -> torch.Tensor:
    """``1_phase``: 1 in the given phases (N,) [-]."""
    return in_phases(s, phases)


def down_velocity_in_contact(
    s: EnvState, phases: tuple[int, ...] = (CROUCH,), threshold_n: float = 1.0
) -> torch.Tensor:
    """``1_phase * 1_contact * -v_z``: downward pelvis speed while a sole is loaded (N,) [m/s]."""
    contact = (s.foot_contact_force_n > threshold_n).any(dim=-1).to(torch.float32)
    return in_phases(s, phases) * contact * -s.base_lin_vel_w[:, 2]


def up_velocity(s: EnvState, phases: tuple[int, ...] = (JUMP,)) -> torch.Tensor:
    """``1_phase * v_z``: upward pelvis speed (world z) (N,) [m/s]."""
    return in_phases(s, phases) * s.base_lin_vel_w[:, 2]


def backward_pitch_rate(s: EnvState, phases: tuple[int, ...] = (JUMP,)) -> torch.Tensor:
    """``1_phase * -w_y``: backward pitch rate of the pelvis (pelvis frame) (N,) [rad/s]."""
    return in_phases(s, phases) * -s.base_ang_vel_b[:, 1]


def land_still(s: EnvState, phases: tuple[int, ...] = (LAND,), scale: float = 10.0) -> torch.Tensor:
    """``1_phase * exp(-scale |v|)`` of the pelvis linear speed |v| [m/s] (``scale`` [s/m])."""
    return in_phases(s, phases) * torch.exp(-scale * s.base_lin_vel_w.norm(dim=-1))


def tilt_angle(s: EnvState, phases: tuple[int, ...] = (STAND, CROUCH, LAND)) -> torch.Tensor:
    """``1_phase * angle(z_base, z_world)`` (N,) [rad]."""
    cos = (-s.projected_gravity_b[:, 2]).clamp(-1.0, 1.0)
    return in_phases(s, phases) * torch.acos(cos)


def lateral_axis_angle(s: EnvState, phases: tuple[int, ...] = (JUMP, AIR)) -> torch.Tensor:
    """``1_phase * angle(y_base, y_world)``: how far the flip axis leaves world y (N,) [rad]."""
    y_b = torch.zeros_like(s.base_pos_w)
    y_b[:, 1] = 1.0
    cos = quat_rotate(s.base_quat_w, y_b)[:, 1].clamp(-1.0, 1.0)
    return in_phases(s, phases) * torch.acos(cos)


def yaw_rate_abs(s: EnvState) -> torch.Tensor:
    """``|w_z|``: pelvis yaw rate magnitude (pelvis frame) (N,) [rad/s]."""
    return s.base_ang_vel_b[:, 2].abs()


def phase_pose_deviation(s: EnvState, source: str = BUILTIN_POSES) -> torch.Tensor:
    """``sum_i 1_phase_i |q - q_des,i|``: Euclidean distance of the joints from the desired pose
    of the env's phase (N,) [rad]; poses from :func:`desired_joint_poses` (``source``)."""
    poses = _poses(source, s.joint_pos_rad.device)
    if poses.shape[0] != s.num_phases:
        raise ValueError(f"desired poses have {poses.shape[0]} phases, the task {s.num_phases}")
    return (s.joint_pos_rad - poses[s.phase]).norm(dim=-1)


# ------------------------------------------------------------------------------ terminations
def tilted_in_phases(
    s: EnvState, max_tilt_rad: float, phases: tuple[int, ...] = (STAND, CROUCH, LAND)
) -> torch.Tensor:
    """Pelvis z tilted beyond ``max_tilt_rad`` [rad] in a ground phase (N,) bool: a fall."""
    return (in_phases(s, phases) > 0) & (-s.projected_gravity_b[:, 2] < math.cos(max_tilt_rad))


# ----------------------------------------------------------------------------------- command
@dataclass(frozen=True)
class StartCommandConfig:
    """``c_t = 1_start``: 0 for a random delay after the reset, then 1 for the episode's rest."""

    dim: int = 1  # command width C [-]
    delay_range_s: tuple[float, float] = (0.3, 1.0)  # time standing before the start [s]

    def __post_init__(self) -> None:
        low, high = self.delay_range_s
        if not 0.0 <= low <= high:
            raise ValueError(
                f"delay_range_s must be (low, high), 0 <= low <= high, got {(low, high)}"
            )
        if self.dim != 1:
            raise ValueError(f"the start command has width 1, got dim={self.dim}")

    def build(self, num_envs: int, generator: torch.Generator) -> Command:
        """The live command."""
        return StartCommand(self, num_envs, generator)


class StartCommand(Command):
    """Per-env timer against a start delay drawn at each reset (:class:`StartCommandConfig`)."""

    reference_anchor_phase = "crouch"  # the oracle's backflip starts its motion with the Crouch

    def __init__(self, cfg: StartCommandConfig, num_envs: int, generator: torch.Generator) -> None:
        self.cfg = cfg
        self.generator = generator
        self.device = generator.device  # the env's device: tensors and draws live there
        self.time_s = torch.zeros(num_envs, device=self.device)
        self.delay_s = torch.zeros(num_envs, device=self.device)

    def reset(self, env_ids: torch.Tensor) -> None:
        """Restart the timers of ``env_ids`` and draw their start delays."""
        low, high = self.cfg.delay_range_s
        self.time_s[env_ids] = 0.0
        self.delay_s[env_ids] = low + (high - low) * torch.rand(
            env_ids.numel(), generator=self.generator, device=self.device
        )

    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Advance the timers by ``dt_s`` [s]; the command (N, 1) is 1 once the delay passed."""
        self.time_s += dt_s
        return (self.time_s >= self.delay_s).to(torch.float32).unsqueeze(-1)

    def columns(self) -> tuple[CommandColumns, ...]:
        """The start signal."""
        low, high = self.cfg.delay_range_s
        return (
            CommandColumns(
                "start", 1, "-",
                "0 while the robot stands, then 1 for the rest of the episode: the signal to "
                f"flip (in training 1 from a delay drawn in [{low:g}, {high:g}] s after the start)",
            ),
        )  # fmt: skip

    def reference_time_s(self) -> torch.Tensor:
        """Time since the start command (N,) [s], negative while the robot waits: an oracle
        artifact's coach follows its reference from the start of its Crouch (the FSM's phases
        switch on the robot's state, so an env may run ahead of or behind this clock)."""
        return (self.time_s - self.delay_s).double()

    def state_dict(self) -> dict[str, Any]:
        """Timers and delays."""
        return {"time_s": self.time_s.clone(), "delay_s": self.delay_s.clone()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the timers."""
        self.time_s = state["time_s"].to(self.device, copy=True)
        self.delay_s = state["delay_s"].to(self.device, copy=True)


# ------------------------------------------------------------------------------------- phases
@dataclass(frozen=True)
class BackflipPhasesConfig:
    """The five-phase backflip FSM (module docstring); heights scaled to the G1 (stand 0.76 m)."""

    names: tuple[str, ...] = BACKFLIP_PHASES  # phase names, FSM order [-]
    crouch_height_m: float = 0.62  # pelvis height below which the crouch turns into the jump [m]
    contact_threshold_n: float = 1.0  # sole normal force counting as contact [N]
    min_turn_rad: float = math.pi  # pitch turned before a touch-down counts as a landing [rad]

    def __post_init__(self) -> None:
        if tuple(self.names) != BACKFLIP_PHASES:
            raise ValueError(f"backflip phases must be {BACKFLIP_PHASES}, got {self.names}")

    def build(self, num_envs: int, generator: torch.Generator) -> PhaseMachine:
        """The live FSM."""
        return BackflipPhaseMachine(self, num_envs, generator.device)


class BackflipPhaseMachine(PhaseMachine):
    """Per-env phase, pitch turned, highest phase and short-landing flag; the record of each env's
    last finished episode is kept (``last_*``) for evaluation."""

    def __init__(
        self, cfg: BackflipPhasesConfig, num_envs: int, device: torch.device | str = "cpu"
    ) -> None:
        self.cfg, self.device, n, dev = cfg, device, num_envs, device
        self.phase = torch.zeros(n, dtype=torch.long, device=dev)
        self.turned_rad = torch.zeros(n, device=dev)
        self.max_phase = torch.zeros(n, dtype=torch.long, device=dev)
        self.landed_short = torch.zeros(n, dtype=torch.bool, device=dev)
        self.fresh = torch.ones(n, dtype=torch.bool, device=dev)
        self.last_max_phase = torch.zeros(n, dtype=torch.long, device=dev)
        self.last_turned_rad = torch.zeros(n, device=dev)
        self.last_landed_short = torch.zeros(n, dtype=torch.bool, device=dev)

    def reset(self, env_ids: torch.Tensor) -> None:
        """Record the finished episodes of ``env_ids`` and put them back in Stand."""
        self.last_max_phase[env_ids] = self.max_phase[env_ids]
        self.last_turned_rad[env_ids] = self.turned_rad[env_ids]
        self.last_landed_short[env_ids] = self.landed_short[env_ids]
        self.phase[env_ids] = STAND
        self.turned_rad[env_ids] = 0.0
        self.max_phase[env_ids] = STAND
        self.landed_short[env_ids] = False
        self.fresh[env_ids] = True

    def update(self, state: EnvState) -> torch.Tensor:
        """Advance every env by at most one phase from ``state`` (after a step); returns (N,)."""
        cfg = self.cfg
        phase = self.phase
        active = ~self.fresh  # a just-reset env shows its former episode's command: wait a step
        self.turned_rad = torch.where(
            active & (phase >= CROUCH),
            self.turned_rad - state.base_ang_vel_b[:, 1] * state.step_dt_s,
            self.turned_rad,
        )
        contact = state.foot_contact_force_n > cfg.contact_threshold_n
        any_contact = contact.any(dim=-1)
        turned = self.turned_rad >= cfg.min_turn_rad
        started = state.command[:, 0] > 0.5 if state.command.shape[1] else torch.zeros_like(active)
        nxt = phase.clone()
        nxt[active & (phase == STAND) & started] = CROUCH
        nxt[active & (phase == CROUCH) & (state.base_pos_w[:, 2] < cfg.crouch_height_m)] = JUMP
        nxt[active & (phase == JUMP) & ~any_contact] = AIR
        touch = active & (phase == AIR) & any_contact
        nxt[touch & turned] = LAND
        self.landed_short |= touch & ~turned
        self.phase = nxt
        self.max_phase = torch.maximum(self.max_phase, nxt)
        self.fresh[:] = False
        return self.phase.clone()

    def log(self) -> dict[str, float]:
        """Fraction of envs in each phase and the mean pitch turned [rad]."""
        out = {
            f"Backflip/phase_{name}": float((self.phase == p).float().mean())
            for p, name in enumerate(self.cfg.names)
        }
        out["Backflip/turned_rad"] = float(self.turned_rad.mean())
        return out

    def state_dict(self) -> dict[str, Any]:
        """Every per-env buffer."""
        return {k: v.clone() for k, v in vars(self).items() if isinstance(v, torch.Tensor)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the buffers (onto this machine's device)."""
        for key, value in state.items():
            setattr(self, key, value.to(self.device, copy=True))


# ------------------------------------------------------------------------------- skill measure
@dataclass(frozen=True)
class BackflipSkillConfig:
    """Skill = success rate of recent counted episodes over ``target_success``.

    An episode succeeds when it runs to its time-out in Land with both soles loaded for at least
    ``hold_s`` (no failure in between) and ends upright and still. Failures count as misses;
    time-outs of episodes shortened by a runner's random episode start are not counted.
    """

    target_success: float = 0.9  # success rate that counts as learned [-]
    window: int = 256  # counted episodes in the moving window [-]
    hold_s: float = 1.0  # both soles loaded in Land for at least this long [s]
    max_tilt_rad: float = 0.35  # pelvis tilt at the end at most [rad]
    max_speed_mps: float = 0.3  # pelvis speed at the end at most [m/s]

    def __post_init__(self) -> None:
        if not 0.0 < self.target_success <= 1.0:
            raise ValueError(f"target_success must be in (0, 1], got {self.target_success}")
        if self.window < 1:
            raise ValueError(f"skill window must be >= 1 episode, got {self.window}")

    def build(self, max_episode_length: int) -> SkillMeasure:
        """The live measure for episodes of ``max_episode_length`` policy steps."""
        return BackflipSkill(self, max_episode_length)


def backflip_success(s: EnvState, cfg: BackflipSkillConfig) -> torch.Tensor:
    """Per env (N,) bool: in Land, soles loaded for ``hold_s``, upright and still (end state)."""
    held = s.foot_contact_time_s.min(dim=-1).values >= cfg.hold_s - 1e-6
    upright = -s.projected_gravity_b[:, 2] >= math.cos(cfg.max_tilt_rad)
    still = s.base_lin_vel_w.norm(dim=-1) <= cfg.max_speed_mps
    return (s.phase == LAND) & held & upright & still


class BackflipSkill(WindowedSkill):
    """Moving window of success (1) / miss (0) flags (see :class:`BackflipSkillConfig`)."""

    def __init__(self, cfg: BackflipSkillConfig, max_episode_length: int) -> None:
        """An empty window of ``cfg.window`` episodes."""
        super().__init__(cfg, cfg.window, max_episode_length)
        self.last_env_ids = torch.zeros(0, dtype=torch.long)
        self.last_success = torch.zeros(0, dtype=torch.bool)

    def episode_scores(
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, state: EnvState
    ) -> torch.Tensor:
        """Landed (1) or not (0), judged from the last state (kept for the evaluator)."""
        success = time_outs & backflip_success(state, self.cfg)[env_ids]
        self.last_env_ids, self.last_success = env_ids.clone(), success.clone()
        return success

    def success_rate(self) -> float:
        """Success fraction of the window (0 before any counted episode) [-]."""
        return self.window.mean()

    def progress(self) -> float:
        """Success rate over ``target_success``."""
        return self.success_rate() / self.cfg.target_success

    def log(self) -> dict[str, float]:
        """The success rate of the window."""
        return {"Skill/backflip_success_rate": self.success_rate()}
