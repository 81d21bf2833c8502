"""The dance's clip library: clip sources loaded once per process, as MuJoCo rows and commands.

``"builtin"`` is the built-in choreography (:func:`optimal_control.dance.built_in_dance`, cached on
disk after its first IK solve), any other source a CSV / NPZ clip path
(:func:`optimal_control.motion_clip.load_motion_clip`, resampled to 50 Hz).
"""

from __future__ import annotations

import hashlib
import inspect
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from optimal_control.files import atomic_save_npz
from rl.tasks.dance.terms import step_displacement, step_rotation

BUILTIN_CLIP = "builtin"
"""Clip source name of the built-in choreography."""


def _cache_dir() -> Path:
    return Path.home() / ".cache" / "a2cf-mb" / "dance"


def _builtin_reference():
    """The built-in dance reference; its IK solve (placo) is cached on disk, keyed by the dance
    config and the source of :mod:`optimal_control.dance`."""
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
        if not sources:
            raise ValueError("the dance task needs at least one clip source")
        return cls.from_references(tuple(sources), [load_reference(s) for s in sources], step_dt_s)

    @classmethod
    def from_references(cls, names: tuple[str, ...], refs: list, step_dt_s: float) -> ClipLibrary:
        """The library of loaded references (one per name), each at the frame step ``step_dt_s``."""
        # MuJoCo's sole heights, not Pinocchio's (the same, tested): the GPU machine has none
        from robots.conventions import pin_to_mj_qpos, pin_to_mj_qvel
        from robots.mujoco_model import build_mujoco_spec, sole_corner_heights_mj, standing_qpos

        spec = build_mujoco_spec()
        stand_floor = sole_corner_heights_mj(standing_qpos(spec)[None], spec).min()
        qpos, qvel, shift, starts, lengths = [], [], [], [], []
        for source, ref in zip(names, refs, strict=True):
            if abs(ref.dt - step_dt_s) > 1e-9:
                raise ValueError(
                    f"dance clip '{source}' has frame step {ref.dt} s, the policy step is "
                    f"{step_dt_s} s: resample the clip to {1 / step_dt_s:g} fps"
                )
            heights = sole_corner_heights_mj(pin_to_mj_qpos(ref.q), spec)
            starts.append(sum(lengths))
            lengths.append(ref.q.shape[0])
            qpos.append(pin_to_mj_qpos(ref.q))
            qvel.append(pin_to_mj_qvel(ref.q, ref.v))
            shift.append(grounded_shift(heights.min(axis=1) - stand_floor, ref.contacts))
        qpos_all, qvel_all = np.concatenate(qpos), np.concatenate(qvel)
        return cls(
            names=tuple(names),
            qpos=qpos_all,
            qvel=qvel_all,
            floor_shift_m=np.concatenate(shift),
            command=frame_commands(qpos_all, qvel_all, step_dt_s),
            start=torch.tensor(starts),
            length=torch.tensor(lengths),
            dt_s=step_dt_s,
        )


def grounded_shift(shift_m: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """Per frame (F,), the floor shift of the nearest frame with a sole in contact (``contacts``
    (F, 2) bool): a frame in the air (a jump, a flip) is lowered as the ground frames around it
    are, not until its soles touch the floor. Unchanged where every frame or none is grounded."""
    grounded = np.flatnonzero(np.asarray(contacts).any(axis=1))
    if grounded.size in (0, shift_m.shape[0]):
        return shift_m
    frames = np.arange(shift_m.shape[0])
    right = grounded[np.clip(np.searchsorted(grounded, frames), 0, grounded.size - 1)]
    left = grounded[np.clip(np.searchsorted(grounded, frames) - 1, 0, None)]
    nearest = np.where(np.abs(frames - left) <= np.abs(right - frames), left, right)
    return shift_m[nearest]


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
