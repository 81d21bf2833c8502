"""The tracking task's motion library: its references, loaded once per process, with the poses
and velocities of the tracked links at every frame (MuJoCo kinematics of the reference).

A source is ``"builtin"`` (the built-in choreography), a clip file (LAFAN1 G1 CSV, our NPZ, the
whole_body_tracking / mjlab motion NPZ) or an oracle artifact folder
(:func:`optimal_control.reference_sources.load_reference`). ``frames`` ``(A, B)`` takes the
segment of source frames A (inclusive) to B (exclusive) of each (the built-in's frames are 50 Hz).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import torch

from rl.envs.state import quat_multiply
from rl.tasks.dance.clips import BUILTIN_CLIP, ClipLibrary, _builtin_reference
from rl.tasks.track.terms import TRACKED_BODIES, quat_conjugate


def load_track_reference(
    source: str,
    frames: tuple[int, int] | None,
    step_dt_s: float | None = None,
    oracle: str = "",
    oracle_phases: bool = False,
):
    """The :class:`optimal_control.reference.Reference` of one source (and segment), at the
    policy step ``step_dt_s`` [s] when given (:func:`at_policy_rate`). ``oracle``: an oracle
    artifact folder solved on this very motion (``train --oracle``): its planned joint torques go
    with the reference (:func:`with_oracle`), and with ``oracle_phases`` its phases (time bins)."""
    from optimal_control.reference_sources import MIN_DURATION_S, load_reference

    if source == BUILTIN_CLIP:
        ref = _builtin_reference()
        if frames is not None:
            a, b = frames
            if not 0 <= a < b <= ref.num_frames:
                raise ValueError(
                    f"--reference-frames {a}:{b} is outside the built-in dance's "
                    f"{ref.num_frames} frames (50 Hz): pick 0 <= A < B <= {ref.num_frames}"
                )
            ref = ref.slice(a, b)
    else:
        ref = load_reference(source, frames=frames, name=Path(source).stem)
        torques = planned_joint_torques_nm(source, frames)
        if torques is not None:
            ref.extras[JOINT_TORQUE_EXTRA] = torques
    if ref.duration_s < MIN_DURATION_S:
        raise ValueError(
            f"reference '{source}' lasts {ref.duration_s:.2f} s, shorter than "
            f"{MIN_DURATION_S:g} s: give a longer clip or a wider --reference-frames segment"
        )
    ref = ref if step_dt_s is None else at_policy_rate(ref, step_dt_s)
    return with_oracle(ref, oracle, oracle_phases) if oracle else ref


def with_oracle(ref, folder: str, phases: bool = False):
    """``ref`` with the joint torques (F, 29) [N m] the oracle artifact in ``folder`` planned it
    with (the per-frame wrench QP's at full strength, alpha 1: contact-consistent, and with the
    pelvis wrench where the motion is not doable unaided) in ``extras``, and with ``phases`` the
    artifact's phases (its time bins, ``solve-dance --phase-bin-s``).

    Raises:
        ValueError: the artifact was solved on another motion (its reference's fingerprint
            differs), naming both.
    """
    from optimal_control.artifact import OracleArtifact
    from optimal_control.reference_sources import reference_fingerprint

    art = OracleArtifact.load(folder)
    solved = at_policy_rate(art.reference, ref.dt)
    if reference_fingerprint(solved) != reference_fingerprint(ref):
        raise ValueError(
            f"oracle artifact {folder} was solved on another motion than the reference "
            f"'{ref.name}' (fingerprints {reference_fingerprint(solved)} and "
            f"{reference_fingerprint(ref)}): solve it on the same clip and segment (train "
            "--oracle does)"
        )
    ref.extras[JOINT_TORQUE_EXTRA] = np.asarray(art.profiles[max(art.profiles)].tau_nm, float)
    if phases:
        ref.phase = np.asarray(solved.phase, dtype=np.int64)
        ref.phase_names = tuple(solved.phase_names)
    return ref


JOINT_TORQUE_EXTRA = "joint_torque_nm"
"""The reference's ``extras`` key of the joint torques it was planned with (F, 29) [N m]."""


def planned_joint_torques_nm(source: str, frames: tuple[int, int] | None) -> np.ndarray | None:
    """The joint torques (F, 29) [N m] an oracle artifact planned its reference with, frames
    ``[A, B)`` of them: the trajectory optimisation's own (``solve-backflip``: consistent with
    its contact forces and pelvis wrench) where the artifact has them, else the per-frame wrench
    QP's at full strength (alpha 1). None for a clip file (no torques were planned)."""
    folder = Path(source)
    if not folder.is_dir():
        return None
    from optimal_control.artifact import OracleArtifact

    art = OracleArtifact.load(folder)
    tau = art.extra_arrays.get("to_tau_nm")
    if tau is None:
        tau = art.profiles[max(art.profiles)].tau_nm  # the strongest robot of the sweep: alpha 1
    tau = np.asarray(tau, dtype=np.float64)
    return tau if frames is None else tau[frames[0] : frames[1]]


def at_policy_rate(ref, step_dt_s: float):
    """``ref`` sampled every ``step_dt_s`` [s] over its span, unchanged where it already is (a
    clip at 50 Hz); an oracle artifact on a finer grid (the backflip's TO) is resampled: q by
    cubic splines and slerp, v and a linearly, contacts and phases from the nearest frame."""
    from optimal_control.motion_clip import resample
    from optimal_control.reference import Reference

    if abs(ref.dt - step_dt_s) <= 1e-9:
        return ref
    q = resample(ref.q, 1.0 / ref.dt, 1.0 / step_dt_s)
    t = np.arange(q.shape[0]) * step_dt_s
    nearest = np.clip(np.rint(t / ref.dt).astype(int), 0, ref.num_frames - 1)

    def linear(x: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, ref.time_s, x[:, k]) for k in range(x.shape[1])], axis=1)

    extras = {
        k: linear(np.asarray(x, dtype=np.float64).reshape(ref.num_frames, -1)).reshape(
            (len(t),) + np.shape(x)[1:]
        )
        for k, x in ref.extras.items()
    }
    return Reference(
        time_s=t, q=q, v=linear(ref.v), a=linear(ref.a), contacts=ref.contacts[nearest],
        phase=ref.phase[nearest], phase_names=ref.phase_names, dt=step_dt_s, name=ref.name,
        extras=extras,
    ).validate()  # fmt: skip


def hold_ends(ref, hold_s: float):
    """``ref`` with its first and last frames held, at rest, for ``hold_s`` [s] before and after
    it (a flip's standing seconds); unchanged for 0. Held frames keep the end frames' contacts and
    phases."""
    from optimal_control.reference import Reference

    n = round(hold_s / ref.dt)
    if n <= 0:
        return ref

    def pad(x: np.ndarray, rest: bool) -> np.ndarray:
        first, last = (np.zeros_like(x[:1]), np.zeros_like(x[-1:])) if rest else (x[:1], x[-1:])
        return np.concatenate([np.repeat(first, n, 0), x, np.repeat(last, n, 0)])

    frames = ref.num_frames + 2 * n
    return Reference(
        time_s=ref.time_s[0] + np.arange(frames) * ref.dt, q=pad(ref.q, False),
        v=pad(ref.v, True), a=pad(ref.a, True), contacts=pad(ref.contacts, False),
        phase=pad(ref.phase, False), phase_names=ref.phase_names, dt=ref.dt, name=ref.name,
        extras={k: pad(np.asarray(x), False) for k, x in ref.extras.items()},
    ).validate()  # fmt: skip


def reference_phase_names(refs: list) -> tuple[str, ...]:
    """The phase names the references share ((): they differ, so no phase is read from them)."""
    names = {tuple(r.phase_names) for r in refs}
    return next(iter(names)) if len(names) == 1 else ()


def pitch_increment_rad(q_from: torch.Tensor, q_to: torch.Tensor) -> torch.Tensor:
    """The signed rotation about the body's own y axis from orientations ``q_from`` to ``q_to``
    (M, 4) w x y z, the short way round (M,) [rad]."""
    rel = quat_multiply(quat_conjugate(q_from), q_to)
    rel = rel * torch.where(rel[:, :1] < 0, -1.0, 1.0)
    sin_half = rel[:, 1:].norm(dim=-1)
    return 2 * torch.atan2(sin_half, rel[:, 0]) * rel[:, 2] / sin_half.clamp_min(1e-12)


def pitch_turn_rad(quat_wxyz: np.ndarray | torch.Tensor) -> float:
    """The pitch turn summed over consecutive orientations (F, 4) w x y z [rad]
    (:func:`pitch_increment_rad`): -2 pi for a backflip, about 0 for a dance."""
    q = torch.as_tensor(np.asarray(quat_wxyz), dtype=torch.float64)
    return float(pitch_increment_rad(q[:-1], q[1:]).sum()) if q.shape[0] > 1 else 0.0


@dataclass
class MotionLibrary:
    """A :class:`ClipLibrary` (frames, floor shifts, start / length per reference) plus, per
    frame, the tracked links' world poses and velocities (float32, (F, K, 3|4)), the joint rates
    (F, 29), the joint torques an oracle artifact planned (F, 29) and each reference's
    contact-free name."""

    clips: ClipLibrary
    body_pos_w: torch.Tensor  # (F, K, 3) link frame positions, before the env's floor offset [m]
    body_quat_w: torch.Tensor  # (F, K, 4) link orientations, w x y z
    body_lin_vel_w: torch.Tensor  # (F, K, 3) [m/s]
    body_ang_vel_w: torch.Tensor  # (F, K, 3) [rad/s]
    joint_pos_rad: torch.Tensor  # (F, 29)
    joint_vel_rps: torch.Tensor  # (F, 29)
    phase: torch.Tensor  # (F,) long, each frame's phase in ``phase_names`` (0 where none)
    phase_names: tuple[str, ...]  # the references' shared phase names; (): they differ
    hold_frames: int  # frames held still before (and after) each reference [-]
    joint_torque_nm: torch.Tensor  # (F, 29) planned joint torques (0 where none were) [N m]
    link_ground_contact: torch.Tensor  # (F, B) bool: link b (not a sole) on the ground
    contact_bodies: tuple[str, ...]  # (B,) the links of ``link_ground_contact``

    @classmethod
    def load(
        cls,
        sources: tuple[str, ...],
        frames: tuple[int, int] | None,
        step_dt_s: float,
        hold_s: float = 0.0,
        oracle: str = "",
        oracle_phases: bool = False,
    ) -> MotionLibrary:
        """Load every source (and segment), its ends held ``hold_s`` [s] (:func:`hold_ends`);
        kinematics of the tracked links at every frame. ``oracle``, ``oracle_phases``: see
        :func:`load_track_reference` (one reference only)."""
        if not sources:
            raise ValueError("the tracking task needs at least one reference (--reference PATH)")
        refs = [
            hold_ends(load_track_reference(s, frames, step_dt_s, oracle, oracle_phases), hold_s)
            for s in sources
        ]
        clips = ClipLibrary.from_references(tuple(sources), refs, step_dt_s)
        pos, quat, lin, ang = link_kinematics(clips.qpos, clips.qvel)
        qpos = torch.as_tensor(clips.qpos).float()
        qvel = torch.as_tensor(clips.qvel).float()
        names = reference_phase_names(refs)
        phase = np.concatenate([r.phase for r in refs]) if names else np.zeros(len(clips.qpos))
        torque = np.concatenate([
            r.extras.get(JOINT_TORQUE_EXTRA, np.zeros((r.num_frames, qpos.shape[1] - 7)))
            for r in refs
        ])  # fmt: skip
        grounded = clips.qpos.copy()
        grounded[:, 2] -= clips.floor_shift_m  # each frame on the floor, as an episode from it
        contact, bodies = link_ground_contacts(grounded)
        return cls(
            clips, pos, quat, lin, ang, qpos[:, 7:], qvel[:, 6:],
            torch.as_tensor(phase, dtype=torch.long), names, round(hold_s / step_dt_s),
            torch.as_tensor(torque).float(), torch.as_tensor(contact), bodies,
        )  # fmt: skip


def link_kinematics(qpos: np.ndarray, qvel: np.ndarray, bodies: tuple[str, ...] = TRACKED_BODIES):
    """World poses and velocities of ``bodies`` at MuJoCo ``qpos`` (F, 36) / ``qvel`` (F, 35):
    the same body sensors the env's state reads (float32 tensors (F, K, 3), (F, K, 4), ...)."""
    from rl.envs.model import build_physics_model, model_layout

    model = build_physics_model(link_collisions=False, tracked_bodies=bodies)
    lay = model_layout(model)
    data = mujoco.MjData(model)
    sens = np.empty((qpos.shape[0], model.nsensordata))
    for f in range(qpos.shape[0]):
        data.qpos[:], data.qvel[:] = qpos[f], qvel[f]
        mujoco.mj_forward(model, data)
        sens[f] = data.sensordata
    sens_t = torch.as_tensor(sens).float()
    return tuple(
        sens_t[:, torch.as_tensor(cols)]
        for cols in (lay.body_pos, lay.body_quat, lay.body_lin_vel, lay.body_ang_vel)
    )


def link_ground_contacts(qpos: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """Which links other than the soles touch the ground at MuJoCo ``qpos`` (F, 36): (F, B) bool
    and the B links (the env's link-contact sensors, on the env's collision model)."""
    from rl.envs.model import build_physics_model, model_layout

    model = build_physics_model(link_collisions=True)
    lay = model_layout(model)
    data = mujoco.MjData(model)
    down = np.zeros((qpos.shape[0], len(lay.contact_bodies)), dtype=bool)
    for f in range(qpos.shape[0]):
        data.qpos[:] = qpos[f]
        mujoco.mj_forward(model, data)
        down[f] = data.sensordata[lay.contact] > 0.5
    return down, tuple(lay.contact_bodies)


_LIBRARIES: dict[tuple, MotionLibrary] = {}


def motion_library(
    sources: tuple[str, ...],
    frames: tuple[int, int] | None,
    step_dt_s: float,
    hold_s: float = 0.0,
    oracle: str = "",
    oracle_phases: bool = False,
) -> MotionLibrary:
    """The (per-process cached) library of ``sources``, ``frames``, ``hold_s`` and the oracle."""
    key = (tuple(sources), frames, float(step_dt_s), float(hold_s), oracle, bool(oracle_phases))
    if key not in _LIBRARIES:
        _LIBRARIES[key] = MotionLibrary.load(*key)
    return _LIBRARIES[key]
