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

from rl.tasks.dance.clips import BUILTIN_CLIP, ClipLibrary, _builtin_reference
from rl.tasks.track.terms import TRACKED_BODIES


def load_track_reference(
    source: str, frames: tuple[int, int] | None, step_dt_s: float | None = None
):
    """The :class:`optimal_control.reference.Reference` of one source (and segment), at the
    policy step ``step_dt_s`` [s] when given (:func:`at_policy_rate`)."""
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
    if ref.duration_s < MIN_DURATION_S:
        raise ValueError(
            f"reference '{source}' lasts {ref.duration_s:.2f} s, shorter than "
            f"{MIN_DURATION_S:g} s: give a longer clip or a wider --reference-frames segment"
        )
    return ref if step_dt_s is None else at_policy_rate(ref, step_dt_s)


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

    return Reference(
        time_s=t, q=q, v=linear(ref.v), a=linear(ref.a), contacts=ref.contacts[nearest],
        phase=ref.phase[nearest], phase_names=ref.phase_names, dt=step_dt_s, name=ref.name,
    ).validate()  # fmt: skip


@dataclass
class MotionLibrary:
    """A :class:`ClipLibrary` (frames, floor shifts, start / length per reference) plus, per
    frame, the tracked links' world poses and velocities (float32, (F, K, 3|4)), the joint rates
    (F, 29) and each reference's contact-free name."""

    clips: ClipLibrary
    body_pos_w: torch.Tensor  # (F, K, 3) link frame positions, before the env's floor offset [m]
    body_quat_w: torch.Tensor  # (F, K, 4) link orientations, w x y z
    body_lin_vel_w: torch.Tensor  # (F, K, 3) [m/s]
    body_ang_vel_w: torch.Tensor  # (F, K, 3) [rad/s]
    joint_pos_rad: torch.Tensor  # (F, 29)
    joint_vel_rps: torch.Tensor  # (F, 29)

    @classmethod
    def load(
        cls, sources: tuple[str, ...], frames: tuple[int, int] | None, step_dt_s: float
    ) -> MotionLibrary:
        """Load every source (and segment); kinematics of the tracked links at every frame."""
        if not sources:
            raise ValueError("the tracking task needs at least one reference (--reference PATH)")
        refs = [load_track_reference(s, frames, step_dt_s) for s in sources]
        clips = ClipLibrary.from_references(tuple(sources), refs, step_dt_s)
        pos, quat, lin, ang = link_kinematics(clips.qpos, clips.qvel)
        qpos = torch.as_tensor(clips.qpos).float()
        qvel = torch.as_tensor(clips.qvel).float()
        return cls(clips, pos, quat, lin, ang, qpos[:, 7:], qvel[:, 6:])


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


_LIBRARIES: dict[tuple, MotionLibrary] = {}


def motion_library(
    sources: tuple[str, ...], frames: tuple[int, int] | None, step_dt_s: float
) -> MotionLibrary:
    """The (per-process cached) library of ``sources`` and ``frames``."""
    key = (tuple(sources), frames, float(step_dt_s))
    if key not in _LIBRARIES:
        _LIBRARIES[key] = MotionLibrary.load(key[0], frames, step_dt_s)
    return _LIBRARIES[key]
