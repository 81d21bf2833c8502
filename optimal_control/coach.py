"""The coach: a model-based, state-dependent pelvis wrench that makes a reference doable in physics.

::

    w(s, t) = clip_eta( g(e) * w_ff(t) + K_p db(pose_ref(t) - pose) + K_d g(e) (twist_ref(t) - twist) )

* ``w_ff(t)``: the oracle's per-frame wrench (the profile of ``CoachConfig.feedforward_alpha``,
  default 1: the least help the real robot needs to follow the reference).
* Pose and twist: the pelvis (origin position and orientation, world linear velocity of the origin,
  world angular velocity). The orientation error is the rotation vector of ``R_ref R^T`` (world).
* Gains from the robot, not tuned per clip: a critically damped second-order error at the natural
  frequency ``natural_frequency_hz`` (omega) for the whole robot: ``K_p = m omega^2``,
  ``K_d = 2 zeta m omega`` on the force axes (m total mass) and ``K_p = I omega^2``,
  ``K_d = 2 zeta omega I`` on the torque axes (I the 3 x 3 centroidal rotational inertia of the
  standing robot, world axes).
* ``clip_eta``: each axis clipped to ``bound_scale * eta0`` of the phase (from the artifact);
  ``bounded=False`` turns the clip off (the help the coach needs, to compare with eta0).
* Tolerance band (assist as needed, ``band_position_m``, ``band_orientation_rad``; 0 = off): the
  pose error is dead-banded radially (``db``), and the feed-forward and damping are scaled by
  ``g(e) = clip(max(|e_p| / band_p, |e_R| / band_R) - 1, 0, 1)``: no help while the pelvis stays
  within the band around the reference, help growing beyond it, full at twice the band.

:class:`Coach` evaluates this batched, for numpy arrays or torch tensors (any device): the RL
side calls :meth:`Coach.wrench` (or :func:`coach_from_artifact`) for its warm start.
:func:`validate_coach` replays a reference in MuJoCo (joint PD on the reference plus the
oracle's feed-forward joint torques, the coach on the pelvis as ``xfrc_applied``) over randomised
friction, payload and pushes, and reports completion and the applied wrench per phase and axis.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from optimal_control.bounds import AXIS_NAMES
from optimal_control.validation import require_finite_fields
from robots.conventions import pin_to_mj_qpos, pin_to_mj_qvel, quat_xyzw_to_wxyz


@dataclass(frozen=True)
class CoachConfig:
    """Gains, bound and tolerance band of the coach."""

    natural_frequency_hz: float = 1.0  # natural frequency of the pelvis pose error [Hz]
    damping_ratio: float = 1.0  # damping ratio of that error dynamics [-]
    feedforward_alpha: float = 1.0  # alpha of the oracle profile used as w_ff [-]
    bound_scale: float = 1.0  # each axis clipped to bound_scale x eta0 of the phase [-]
    bounded: bool = True  # clip to the bound (False: the coach's full wrench) [-]
    band_position_m: float = 0.0  # tolerance band on the pelvis position error; 0 = none [m]
    band_orientation_rad: float = 0.0  # tolerance band on the orientation error; 0 = none [rad]

    def __post_init__(self) -> None:
        """Reject NaN / inf values and bad signs, naming the field."""
        require_finite_fields(self)
        for name in ("natural_frequency_hz", "damping_ratio", "bound_scale"):
            if getattr(self, name) < 0:
                raise ValueError(f"CoachConfig.{name} must be >= 0, got {getattr(self, name)}.")
        if (self.band_position_m > 0) != (self.band_orientation_rad > 0):
            raise ValueError(
                "CoachConfig: give both band_position_m and band_orientation_rad (> 0) or neither."
            )


def coach_gains(robot=None, cfg: CoachConfig = CoachConfig()) -> dict[str, np.ndarray]:
    """K_p, K_d for force (3 x 3) [N/m, N s/m] and torque (3 x 3) [N m/rad, N m s/rad] axes.

    From the total mass and the centroidal rotational inertia of the standing robot (world axes).
    """
    from robots.pinocchio_model import build_pinocchio_model

    robot = robot or build_pinocchio_model()
    data = robot.data()
    pin.ccrba(robot.model, data, robot.q_stand, np.zeros(robot.model.nv))
    inertia = np.asarray(data.Ig.inertia, dtype=float)
    mass = robot.total_mass_kg
    omega = 2.0 * np.pi * cfg.natural_frequency_hz
    zeta = cfg.damping_ratio
    eye = np.eye(3)
    return {
        "kp_force": mass * omega**2 * eye,
        "kd_force": 2.0 * zeta * mass * omega * eye,
        "kp_torque": inertia * omega**2,
        "kd_torque": 2.0 * zeta * omega * inertia,
        "mass_kg": np.array(mass),
        "inertia_kg_m2": inertia,
    }


def _quat_mul(a, b, xp):
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return xp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def rotation_error_w(quat_ref_wxyz, quat_wxyz):
    """Rotation vector (..., 3) [rad], world axes, of ``R_ref R^T`` (torch tensors)."""
    import torch

    conj = quat_wxyz * torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=quat_wxyz.dtype).to(quat_wxyz)
    err = _quat_mul(quat_ref_wxyz, conj, torch)
    err = torch.where(err[..., :1] < 0, -err, err)
    vec = err[..., 1:]
    norm = torch.linalg.norm(vec, dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(norm, err[..., :1])
    scale = torch.where(norm > 1e-9, angle / norm.clamp_min(1e-12), torch.full_like(norm, 2.0))
    return vec * scale


class Coach:
    """The coach of one reference (see the module docstring). Build with :func:`coach_from_artifact`.

    Reference arrays (T frames, step ``dt_s``): pelvis position (T, 3) [m] and quaternion wxyz
    (T, 4), world linear velocity (T, 3) [m/s] and angular velocity (T, 3) [rad/s], feed-forward
    wrench (T, 6) [N, N m] and bound (T, 6) [N, N m] (eta of each frame's phase), phase (T,).
    """

    def __init__(
        self,
        dt_s: float,
        pos_w: np.ndarray,
        quat_wxyz: np.ndarray,
        lin_vel_w: np.ndarray,
        ang_vel_w: np.ndarray,
        wrench_ff_w: np.ndarray,
        eta: np.ndarray,
        phase: np.ndarray,
        gains: dict[str, np.ndarray],
        cfg: CoachConfig = CoachConfig(),
    ):
        self.dt_s = float(dt_s)
        self.cfg = cfg
        self.gains = gains
        self.phase = np.asarray(phase)
        self._np = {
            "pos": pos_w,
            "quat": quat_wxyz,
            "lin": lin_vel_w,
            "ang": ang_vel_w,
            "ff": wrench_ff_w,
            "eta": eta,
            "kp_f": gains["kp_force"],
            "kd_f": gains["kd_force"],
            "kp_m": gains["kp_torque"],
            "kd_m": gains["kd_torque"],
        }
        self._cache: dict = {}
        self.num_frames = int(pos_w.shape[0])

    def _tables(self, like):
        import torch

        key = (like.device, like.dtype)
        if key not in self._cache:
            self._cache[key] = {
                k: torch.as_tensor(np.asarray(v, dtype=np.float64)).to(like)
                for k, v in self._np.items()
            }
        return self._cache[key]

    def frame_index(self, time_s):
        """Nearest reference frame (N,) of times (N,) [s], clipped to the reference (numpy)."""
        return np.clip(np.rint(np.asarray(time_s) / self.dt_s).astype(int), 0, self.num_frames - 1)

    def wrench(self, pos_w, quat_wxyz, lin_vel_w, ang_vel_w, time_s):
        """Coach wrench (N, 6) [N, N m] (world force, world torque at the pelvis CoM: MuJoCo
        ``xfrc_applied``) for a batch of pelvis states and times.

        Args:
            pos_w: (N, 3) pelvis origin positions [m], world.
            quat_wxyz: (N, 4) pelvis orientations, world, w first (MuJoCo qpos layout).
            lin_vel_w: (N, 3) pelvis origin linear velocities [m/s], world (MuJoCo qvel[0:3]).
            ang_vel_w: (N, 3) pelvis angular velocities [rad/s], world.
            time_s: (N,) time along the reference [s].

        Numpy in, numpy out (float64); torch in, torch out (same device and dtype).
        """
        import torch

        is_torch = isinstance(pos_w, torch.Tensor)
        if is_torch:
            like = pos_w
            args = [torch.as_tensor(x).to(like) for x in (quat_wxyz, lin_vel_w, ang_vel_w)]
            t = torch.as_tensor(time_s).to(like)
        else:
            like = torch.as_tensor(np.asarray(pos_w, dtype=np.float64))
            args = [
                torch.as_tensor(np.asarray(x, dtype=np.float64))
                for x in (quat_wxyz, lin_vel_w, ang_vel_w)
            ]
            t = torch.as_tensor(np.asarray(time_s, dtype=np.float64))
        quat, lin, ang = args
        tab = self._tables(like)
        # Linear interpolation between frames (orientation: nearest frame).
        s = (t / self.dt_s).clamp(0.0, self.num_frames - 1.0)
        k0 = s.floor().long().clamp(max=self.num_frames - 2) if self.num_frames > 1 else s.long()
        k1 = (k0 + 1).clamp(max=self.num_frames - 1)
        lam = (s - k0.to(s.dtype)).unsqueeze(-1)

        def interp(name):
            return (1 - lam) * tab[name][k0] + lam * tab[name][k1]

        kn = torch.where(lam.squeeze(-1) < 0.5, k0, k1)
        e_p = interp("pos") - like
        e_r = rotation_error_w(tab["quat"][kn], quat)
        e_v = interp("lin") - lin
        e_w = interp("ang") - ang
        cfg = self.cfg
        gate = torch.ones_like(e_p[..., :1])
        if cfg.band_position_m > 0:
            n_p = torch.linalg.norm(e_p, dim=-1, keepdim=True)
            n_r = torch.linalg.norm(e_r, dim=-1, keepdim=True)
            e_p = e_p * (1 - cfg.band_position_m / n_p.clamp_min(1e-12)).clamp_min(0.0)
            e_r = e_r * (1 - cfg.band_orientation_rad / n_r.clamp_min(1e-12)).clamp_min(0.0)
            excess = torch.maximum(n_p / cfg.band_position_m, n_r / cfg.band_orientation_rad) - 1
            gate = excess.clamp(0.0, 1.0)
        force = e_p @ tab["kp_f"].T + gate * (e_v @ tab["kd_f"].T)
        torque = e_r @ tab["kp_m"].T + gate * (e_w @ tab["kd_m"].T)
        w = gate * interp("ff") + torch.cat([force, torque], dim=-1)
        eta = tab["eta"][kn]
        w = torch.maximum(torch.minimum(w, eta), -eta)
        return w if is_torch else w.numpy()


def coach_from_artifact(art, cfg: CoachConfig = CoachConfig(), robot=None) -> Coach:
    """The :class:`Coach` of an oracle artifact (an :class:`OracleArtifact` or its folder)."""
    from optimal_control.artifact import OracleArtifact

    if not isinstance(art, OracleArtifact):
        art = OracleArtifact.load(art)
    ref = art.reference
    prof = art.profiles[art._alpha_lookup(cfg.feedforward_alpha)]
    rot = np.array([pin.Quaternion(*q[3:7][[3, 0, 1, 2]]).matrix() for q in ref.q])  # wxyz ctor
    lin_w = np.einsum("tij,tj->ti", rot, ref.v[:, :3])
    ang_w = np.einsum("tij,tj->ti", rot, ref.v[:, 3:6])
    eta = cfg.bound_scale * np.asarray(art.eta0)[ref.phase]
    if not cfg.bounded:
        eta = np.full_like(eta, 1e9)  # no clipping
    return Coach(
        ref.dt,
        ref.q[:, :3].copy(),
        quat_xyzw_to_wxyz(ref.q[:, 3:7]),
        lin_w,
        ang_w,
        prof.wrench_w,
        eta,
        ref.phase,
        coach_gains(robot, cfg),
        cfg,
    )


@dataclass(frozen=True)
class Randomisation:
    """Ranges of the domain randomisation of a validation episode (uniform draws)."""

    friction: tuple[float, float] = (0.5, 1.25)  # sole and floor sliding friction [-]
    payload_kg: tuple[float, float] = (0.0, 3.0)  # mass added to the pelvis [kg]
    push_force_n: tuple[float, float] = (40.0, 100.0)  # horizontal push on the pelvis [N]
    push_duration_s: float = 0.2  # duration of each push [s]
    pushes: int = 2  # pushes per episode, at uniform random times [-]


@dataclass(frozen=True)
class ValidationConfig:
    """How the coach is validated in MuJoCo."""

    episodes: int = 5  # randomised episodes per variant [-]
    seed: int = 0  # random generator seed [-]
    decimation: int = 4  # physics steps per coach / target update (50 Hz) [-]
    joint_feedforward: bool = True  # add the oracle's alpha = 1 joint torques [-]
    fall_height_ratio: float = 0.6  # pelvis below this share of the reference height: fall [-]
    fall_tilt_rad: float = 1.0  # pelvis tilted more than this from the reference: fall [rad]
    max_position_error_m: float = 0.5  # pelvis farther than this from the reference: failed [m]
    band_position_m: float = 0.05  # band of the assist-as-needed variant [m]
    band_orientation_rad: float = 0.15  # band of the assist-as-needed variant [rad]


@dataclass
class Episode:
    """One MuJoCo replay of a reference."""

    completed: bool  # reached the end without falling or drifting off
    end_time_s: float  # time of the fall or of the end [s]
    wrench_w: np.ndarray  # (K, 6) coach wrench at each control step [N, N m]
    phase: np.ndarray  # (K,) reference phase at each control step
    max_position_error_m: float  # largest pelvis position error [m]
    reason: str = ""  # why it ended early: "height", "tilt", "drift", "unstable"; "" = completed


def run_episode(
    coach: Coach | None,
    art,
    model,
    cfg: ValidationConfig,
    rng: np.random.Generator | None = None,
    rand: Randomisation | None = None,
) -> Episode:
    """Replay ``art.reference`` in MuJoCo: joint PD on the reference (+ feed-forward torques),
    ``coach`` on the pelvis (None: no help); ``rand`` draws friction, payload and pushes."""
    import mujoco

    ref = art.reference
    m = copy.deepcopy(model)
    pushes = []
    if rand is not None:
        rng = rng or np.random.default_rng(0)
        m.geom_friction[:, 0] = rng.uniform(*rand.friction)
        m.body_mass[1] += rng.uniform(*rand.payload_kg)
        for _ in range(rand.pushes):
            start = rng.uniform(0.1, max(0.2, ref.duration_s - rand.push_duration_s))
            angle = rng.uniform(0, 2 * np.pi)
            mag = rng.uniform(*rand.push_force_n)
            pushes.append(
                (start, start + rand.push_duration_s, mag * np.cos(angle), mag * np.sin(angle))
            )
    d = mujoco.MjData(m)
    d.qpos[:] = pin_to_mj_qpos(ref.q[0])
    d.qvel[:] = pin_to_mj_qvel(ref.q[0], ref.v[0])
    mujoco.mj_forward(m, d)
    tau_ff = art.profiles[art._alpha_lookup(1.0)].tau_nm if 1.0 in art.profiles else None
    dt_ctrl = m.opt.timestep * cfg.decimation
    steps = int(np.floor(ref.duration_s / dt_ctrl))
    z_ref = ref.q[:, 2]
    wrenches, phases, max_err = [], [], 0.0
    completed, t, reason = True, 0.0, ""
    for k in range(steps):
        t = k * dt_ctrl
        f = min(int(round(t / ref.dt)), ref.num_frames - 1)
        d.ctrl[:] = ref.q[f, 7:]
        if cfg.joint_feedforward and tau_ff is not None:
            d.qfrc_applied[6:] = tau_ff[f]
        w_sum = np.zeros(6)
        for _ in range(cfg.decimation):
            # The coach runs at the physics rate: its damping acts on the light pelvis (3.8 kg)
            # through compliant joints, and K_d dt / m_pelvis must stay well below 2.
            w = np.zeros(6)
            if coach is not None:
                rot = d.xmat[1].reshape(3, 3)
                w = coach.wrench(
                    d.qpos[None, :3],
                    d.qpos[None, 3:7],
                    d.qvel[None, :3],
                    (rot @ d.qvel[3:6])[None],
                    np.array([d.time]),
                )[0]
            push = np.zeros(6)
            for a, b, fx, fy in pushes:
                if a <= d.time < b:
                    push[:2] += (fx, fy)
            d.xfrc_applied[1] = w + push
            mujoco.mj_step(m, d)
            w_sum += w
        w = w_sum / cfg.decimation
        wrenches.append(w)
        phases.append(ref.phase[f])
        err = float(np.linalg.norm(d.qpos[:3] - ref.q[f, :3]))
        max_err = max(max_err, err)
        rot = d.xmat[1].reshape(3, 3)
        ref_rot = pin.Quaternion(*ref.q[f, 3:7][[3, 0, 1, 2]]).matrix()
        tilt = np.arccos(np.clip(np.dot(rot[:, 2], ref_rot[:, 2]), -1.0, 1.0))
        reason = (
            "unstable"
            if not np.all(np.isfinite(d.qpos))
            else "height"
            if d.qpos[2] < cfg.fall_height_ratio * z_ref[f]
            else "tilt"
            if tilt > cfg.fall_tilt_rad
            else "drift"
            if err > cfg.max_position_error_m
            else ""
        )
        if reason:
            completed = False
            break
    return Episode(
        completed, t, np.array(wrenches).reshape(-1, 6), np.array(phases), max_err, reason
    )


def _wrench_stats(episodes: list[Episode], phase_names: tuple[str, ...]) -> dict:
    w = np.concatenate([e.wrench_w for e in episodes]) if episodes else np.zeros((0, 6))
    p = np.concatenate([e.phase for e in episodes]) if episodes else np.zeros(0, int)
    out = {}
    for i, name in enumerate(phase_names):
        rows = np.abs(w[p == i])
        out[name] = (
            {
                "mean": dict(zip(AXIS_NAMES, rows.mean(axis=0).tolist(), strict=True)),
                "p95": dict(zip(AXIS_NAMES, np.percentile(rows, 95, axis=0).tolist(), strict=True)),
            }
            if rows.shape[0]
            else None
        )
    return out


def validate_coach(
    art, coach_cfg: CoachConfig = CoachConfig(), cfg: ValidationConfig = ValidationConfig()
) -> dict:
    """Completion and applied coach wrench of ``art``'s reference in MuJoCo (JSON-ready).

    Variants: no help; the coach clipped to eta0 (``coach_eta0``); the coach unclipped
    (``coach``); the unclipped coach with its tolerance band (``coach_band``); each nominal (one
    episode) and randomised (``cfg.episodes`` episodes: friction, payload and pushes of
    :class:`Randomisation`, the same draws for every variant).
    """
    from robots.mujoco_model import build_mujoco_model

    model = build_mujoco_model()
    free = dataclasses.replace(coach_cfg, bounded=False)
    band_cfg = dataclasses.replace(
        free, band_position_m=cfg.band_position_m, band_orientation_rad=cfg.band_orientation_rad
    )
    variants = {
        "no_help": None,
        "coach_eta0": coach_from_artifact(art, dataclasses.replace(coach_cfg, bounded=True)),
        "coach": coach_from_artifact(art, free),
        "coach_band": coach_from_artifact(art, band_cfg),
    }
    report = {
        "reference": art.reference.name,
        "task": art.task,
        "duration_s": art.reference.duration_s,
        "coach_config": dataclasses.asdict(coach_cfg),
        "validation_config": dataclasses.asdict(cfg),
        "randomisation": dataclasses.asdict(Randomisation()),
        "gains": {k: np.asarray(v).tolist() for k, v in variants["coach"].gains.items()},
        "eta0": np.asarray(art.eta0).tolist(),
        "phase_names": list(art.phase_names),
        "variants": {},
    }
    start = time.perf_counter()
    for name, coach in variants.items():
        nominal = run_episode(coach, art, model, cfg)
        rng = np.random.default_rng(cfg.seed)
        randomised = [
            run_episode(coach, art, model, cfg, rng, Randomisation()) for _ in range(cfg.episodes)
        ]
        report["variants"][name] = {
            "nominal_completed": nominal.completed,
            "nominal_end_time_s": nominal.end_time_s,
            "nominal_max_position_error_m": nominal.max_position_error_m,
            "nominal_end_reason": nominal.reason,
            "randomised_end_reasons": [e.reason for e in randomised],
            "randomised_completion_rate": float(np.mean([e.completed for e in randomised])),
            "randomised_end_time_s": [e.end_time_s for e in randomised],
            "applied_wrench_per_phase": _wrench_stats([nominal, *randomised], art.phase_names),
        }
    report["wall_time_s"] = time.perf_counter() - start
    return report


def write_coach_report(report: dict, folder: str | Path) -> list[Path]:
    """Write ``coach.json`` and ``coach.png`` (completion per variant, mean |w| per axis beside
    eta0) into ``folder``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from optimal_control.files import atomic_savefig, atomic_write_json

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = [atomic_write_json(folder / "coach.json", report)]
    names = report["phase_names"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    variants = list(report["variants"])
    nominal = [float(report["variants"][v]["nominal_completed"]) for v in variants]
    rand = [report["variants"][v]["randomised_completion_rate"] for v in variants]
    x = np.arange(len(variants))
    axes[0].bar(x - 0.2, nominal, 0.4, label="nominal")
    axes[0].bar(x + 0.2, rand, 0.4, label="randomised")
    axes[0].set_xticks(x, variants)
    axes[0].set_ylabel("completion [-]")
    axes[0].set_ylim(0, 1.05)
    axes[0].legend()
    stats = report["variants"]["coach"]["applied_wrench_per_phase"]
    width = 0.8 / (2 * len(names))
    eta0 = np.asarray(report["eta0"])
    for p, name in enumerate(names):
        if stats[name] is None:
            continue
        mean = [stats[name]["mean"][a] for a in AXIS_NAMES]
        axes[1].bar(np.arange(6) + 2 * p * width, mean, width, label=f"coach mean |w| {name}")
        axes[1].bar(
            np.arange(6) + (2 * p + 1) * width, eta0[p], width, alpha=0.4, label=f"eta0 {name}"
        )
    axes[1].set_xticks(np.arange(6) + 0.4, AXIS_NAMES)
    axes[1].set_ylabel("[N, N m]")
    axes[1].legend(fontsize=6)
    fig.suptitle(f"coach in MuJoCo: {report['task']} ({report['duration_s']:.1f} s)")
    fig.tight_layout()
    paths.append(folder / "coach.png")
    atomic_savefig(fig, paths[-1], dpi=90)
    plt.close(fig)
    return paths


def coach_artifact(
    folder: str | Path,
    coach_cfg: CoachConfig = CoachConfig(),
    cfg: ValidationConfig = ValidationConfig(),
    out: str = "",
) -> tuple[dict, Path]:
    """Validate the coach of the artifact in ``folder`` and write ``coach.json`` + ``coach.png``
    to ``out`` (default: the sibling folder ``<artifact>-coach``, so the artifact's manifest
    stays as it is). Returns the report and the output folder."""
    from optimal_control.artifact import OracleArtifact

    folder = Path(folder)
    art = OracleArtifact.load(folder)
    report = validate_coach(art, coach_cfg, cfg)
    report["artifact"] = str(folder)
    target = Path(out) if out else folder.with_name(folder.name + "-coach")
    write_coach_report(report, target)
    return report, target


def format_coach_summary(report: dict, folder: Path) -> str:
    """A few terminal lines: completion per variant and the coach's mean |w| per phase."""
    lines = [f"coach report: {folder} ({report['task']}, {report['duration_s']:.1f} s)"]
    for name, v in report["variants"].items():
        lines.append(
            f"  {name}: nominal {'completed' if v['nominal_completed'] else 'FAILED'} "
            f"({v['nominal_end_reason'] or 'end'} at {v['nominal_end_time_s']:.2f} s), "
            f"randomised {100 * v['randomised_completion_rate']:.0f} % completed"
        )
    stats = report["variants"]["coach"]["applied_wrench_per_phase"]
    for p, phase in enumerate(report["phase_names"]):
        if stats[phase] is None:
            continue
        mean = ", ".join(f"{stats[phase]['mean'][a]:.1f}" for a in AXIS_NAMES)
        eta = ", ".join(f"{x:.1f}" for x in report["eta0"][p])
        lines.append(f"  coach mean |w| [{phase}]: [{mean}] vs eta0 [{eta}] (N, N m)")
    return "\n".join(lines)
