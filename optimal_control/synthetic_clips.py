"""Synthetic "retargeted" clips: a clean reference with the artefacts retargeting adds.

Public retargeted clips (e.g. the G1 LAFAN1 set, CC BY-NC-ND, never committed) are not clean:
the feet hover above or sink into the floor by a few centimetres, slowly, a foot snaps through the
floor for a single frame now and then, the rate is 30 fps and every channel carries noise. Tests
need such data without downloading anything: :func:`retargeted_rows` turns a clean
:class:`~optimal_control.reference.Reference` (e.g. a placo walk) into clip rows (T, 36) in the CSV
layout of :mod:`optimal_control.motion_clip`, with those artefacts drawn from a seeded generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from optimal_control.reference import Reference
from optimal_control.validation import require_finite_fields


@dataclass(frozen=True)
class RetargetArtefacts:
    """What retargeting adds to a clean motion."""

    fps: float = 30.0  # clip frame rate [1/s]
    height_offset_m: float = 0.02  # constant hover of the whole clip above the floor [m]
    drift_amplitude_m: float = 0.02  # slow sinking / hovering of the whole body, amplitude [m]
    drift_period_s: float = 3.0  # period of that drift [s]
    outlier_share: float = 0.02  # share of frames with a one-frame penetration outlier [-]
    outlier_depth_m: float = 0.06  # how far such a frame sinks the body (soles below floor) [m]
    base_noise_m: float = 0.002  # white noise on the base position, std [m]
    joint_noise_rad: float = 0.005  # white noise on the joints, std [rad]
    seed: int = 0  # random generator seed [-]

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field."""
        require_finite_fields(self)


def retargeted_rows(ref: Reference, art: RetargetArtefacts = RetargetArtefacts()) -> np.ndarray:
    """Clip rows (T, 36) [m, quat xyzw, rad] at ``art.fps`` from ``ref`` with retargeting artefacts.

    The clean reference is resampled to ``art.fps`` (linear for positions and joints, slerp for the
    orientation), then: constant hover, sinusoidal drift, noise, and single-frame outliers (the
    base dropped by ``outlier_depth_m`` for one frame, which puts the soles through the floor).
    """
    rng = np.random.default_rng(art.seed)
    t = np.arange(0.0, ref.time_s[-1] + 1e-9, 1.0 / art.fps)
    rows = np.empty((t.shape[0], ref.q.shape[1]))
    for c in (*range(3), *range(7, ref.q.shape[1])):
        rows[:, c] = np.interp(t, ref.time_s, ref.q[:, c])
    rows[:, 3:7] = Slerp(ref.time_s, Rotation.from_quat(ref.q[:, 3:7]))(t).as_quat()
    rows[:, 2] += art.height_offset_m + art.drift_amplitude_m * np.sin(
        2 * np.pi * t / art.drift_period_s
    )
    rows[:, :3] += rng.normal(0.0, art.base_noise_m, (t.shape[0], 3))
    rows[:, 7:] += rng.normal(0.0, art.joint_noise_rad, (t.shape[0], rows.shape[1] - 7))
    count = int(round(art.outlier_share * t.shape[0]))
    if count:
        frames = rng.choice(np.arange(2, t.shape[0] - 2), size=count, replace=False)
        rows[frames, 2] -= art.outlier_depth_m
    return rows
