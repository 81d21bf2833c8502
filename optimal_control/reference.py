"""A whole-body reference motion of the G1: the input of the wrench oracle.

A :class:`Reference` is a uniformly sampled trajectory in Pinocchio conventions (see
:mod:`robots.pinocchio_model`) with a contact schedule and a phase label per frame::

    time_s    (T,)     sample times [s], uniform step dt starting at 0
    q         (T, 36)  configurations [p_w, quat xyzw, 29 joints]
    v         (T, 35)  velocities [v_b (pelvis frame), omega_b, joint rates]
    a         (T, 35)  accelerations, same layout as v
    contacts  (T, 2)   bool, sole in contact [left, right] (order of robots.g1.SOLE_FRAMES)
    phase     (T,)     int index into phase_names
    phase_names        names of the task phases (e.g. ("double_support", "single_support"))

Every producer (walk generator, dance clip, backflip TO) builds one and calls :meth:`validate`, so
consumers (the QP, the artifact, the renderer) can rely on shapes, finiteness and unit quaternions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robots import g1

NQ = 7 + g1.NUM_JOINTS
"""Configuration size (36)."""
NV = 6 + g1.NUM_JOINTS
"""Velocity size (35)."""


class ReferenceError(ValueError):
    """A reference motion is malformed (shapes, NaN, quaternions, phases)."""


@dataclass
class Reference:
    """A sampled whole-body motion with contacts and phases (shapes in the module docstring)."""

    time_s: np.ndarray  # (T,) sample times [s]
    q: np.ndarray  # (T, 36) Pinocchio configurations
    v: np.ndarray  # (T, 35) Pinocchio velocities
    a: np.ndarray  # (T, 35) Pinocchio accelerations
    contacts: np.ndarray  # (T, 2) bool, [left, right] sole in contact
    phase: np.ndarray  # (T,) int phase index per frame
    phase_names: tuple[str, ...]  # names of the phases
    dt: float  # sample step [s]
    name: str = "reference"  # short label (task name)
    extras: dict[str, np.ndarray] = field(default_factory=dict)  # task-specific (T, ...) arrays

    @property
    def num_frames(self) -> int:
        """Number of frames T."""
        return int(self.time_s.shape[0])

    @property
    def duration_s(self) -> float:
        """Duration covered by the samples [s]."""
        return float(self.time_s[-1] - self.time_s[0]) if self.num_frames else 0.0

    def validate(self) -> Reference:
        """Check shapes, dtypes, finiteness, unit quaternions, phases; return ``self``.

        Raises:
            ReferenceError: naming the offending field and what is expected.
        """
        t = self.num_frames
        if t < 1:
            raise ReferenceError(f"Reference '{self.name}' has no frames.")
        expected = {
            "time_s": (t,),
            "q": (t, NQ),
            "v": (t, NV),
            "a": (t, NV),
            "contacts": (t, 2),
            "phase": (t,),
        }
        for key, shape in expected.items():
            value = np.asarray(getattr(self, key))
            if value.shape != shape:
                raise ReferenceError(
                    f"Reference '{self.name}': field '{key}' has shape {value.shape}, expected "
                    f"{shape} (T = {t} frames, q in Pinocchio layout of 36, v/a of 35)."
                )
        for key in ("time_s", "q", "v", "a"):
            value = np.asarray(getattr(self, key), dtype=float)
            if not np.all(np.isfinite(value)):
                frame = int(np.argwhere(~np.isfinite(value.reshape(t, -1)))[0, 0])
                raise ReferenceError(
                    f"Reference '{self.name}': field '{key}' has NaN/inf (first at frame {frame})."
                )
        if not self.dt > 0:
            raise ReferenceError(f"Reference '{self.name}': dt must be > 0, got {self.dt}.")
        if t > 1 and not np.allclose(np.diff(self.time_s), self.dt, atol=1e-6):
            raise ReferenceError(
                f"Reference '{self.name}': time_s is not uniformly sampled at dt = {self.dt} s."
            )
        norms = np.linalg.norm(self.q[:, 3:7], axis=1)
        if not np.allclose(norms, 1.0, atol=1e-6):
            bad = int(np.argmax(np.abs(norms - 1.0)))
            raise ReferenceError(
                f"Reference '{self.name}': base quaternion of frame {bad} has norm {norms[bad]:.6f};"
                " normalise q[:, 3:7] (xyzw)."
            )
        if not self.phase_names:
            raise ReferenceError(f"Reference '{self.name}': phase_names is empty.")
        phase = np.asarray(self.phase)
        if phase.min() < 0 or phase.max() >= len(self.phase_names):
            raise ReferenceError(
                f"Reference '{self.name}': phase indices must lie in [0, {len(self.phase_names)})"
                f" for phase_names {self.phase_names}, got [{phase.min()}, {phase.max()}]."
            )
        for key, value in self.extras.items():
            if np.asarray(value).shape[:1] != (t,):
                raise ReferenceError(
                    f"Reference '{self.name}': extra '{key}' must have T = {t} rows, got shape "
                    f"{np.asarray(value).shape}."
                )
        self.time_s = np.asarray(self.time_s, dtype=float)
        self.q = np.asarray(self.q, dtype=float)
        self.v = np.asarray(self.v, dtype=float)
        self.a = np.asarray(self.a, dtype=float)
        self.contacts = np.asarray(self.contacts, dtype=bool)
        self.phase = np.asarray(self.phase, dtype=np.int64)
        self.phase_names = tuple(self.phase_names)
        return self

    def slice(self, start: int, stop: int | None = None) -> Reference:
        """Frames ``[start, stop)`` as a new reference with time restarting at 0."""
        sel = slice(start, stop)
        time_s = self.time_s[sel] - self.time_s[sel][0]
        return Reference(
            time_s=time_s,
            q=self.q[sel].copy(),
            v=self.v[sel].copy(),
            a=self.a[sel].copy(),
            contacts=self.contacts[sel].copy(),
            phase=self.phase[sel].copy(),
            phase_names=self.phase_names,
            dt=self.dt,
            name=self.name,
            extras={k: np.asarray(v)[sel].copy() for k, v in self.extras.items()},
        ).validate()

    def to_arrays(self, prefix: str = "ref_") -> dict[str, np.ndarray]:
        """Arrays for an npz file, keys prefixed (extras as ``<prefix>extra_<key>``)."""
        arrays = {
            f"{prefix}time_s": self.time_s,
            f"{prefix}q": self.q,
            f"{prefix}v": self.v,
            f"{prefix}a": self.a,
            f"{prefix}contacts": self.contacts,
            f"{prefix}phase": self.phase,
        }
        arrays.update({f"{prefix}extra_{k}": np.asarray(v) for k, v in self.extras.items()})
        return arrays

    @classmethod
    def from_arrays(
        cls,
        arrays: dict[str, np.ndarray],
        phase_names: tuple[str, ...],
        name: str,
        prefix: str = "ref_",
    ) -> Reference:
        """Inverse of :meth:`to_arrays` (``dt`` is recovered from ``time_s``)."""
        time_s = np.asarray(arrays[f"{prefix}time_s"], dtype=float)
        dt = float(time_s[1] - time_s[0]) if time_s.shape[0] > 1 else 1.0
        extra_prefix = f"{prefix}extra_"
        return cls(
            time_s=time_s,
            q=np.asarray(arrays[f"{prefix}q"]),
            v=np.asarray(arrays[f"{prefix}v"]),
            a=np.asarray(arrays[f"{prefix}a"]),
            contacts=np.asarray(arrays[f"{prefix}contacts"]),
            phase=np.asarray(arrays[f"{prefix}phase"]),
            phase_names=tuple(phase_names),
            dt=dt,
            name=name,
            extras={
                k[len(extra_prefix) :]: np.asarray(v)
                for k, v in arrays.items()
                if k.startswith(extra_prefix)
            },
        ).validate()


def static_reference(
    q: np.ndarray,
    num_frames: int,
    dt: float,
    contacts: tuple[bool, bool] = (True, True),
    name: str = "static",
) -> Reference:
    """A motionless reference holding configuration ``q`` (36,) for ``num_frames`` frames."""
    q = np.asarray(q, dtype=float)
    return Reference(
        time_s=np.arange(num_frames) * dt,
        q=np.tile(q, (num_frames, 1)),
        v=np.zeros((num_frames, NV)),
        a=np.zeros((num_frames, NV)),
        contacts=np.tile(np.asarray(contacts, dtype=bool), (num_frames, 1)),
        phase=np.zeros(num_frames, dtype=np.int64),
        phase_names=("static",),
        dt=dt,
        name=name,
    ).validate()
