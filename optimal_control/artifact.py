"""The OracleArtifact: what the oracle hands to learning, on disk, versioned and validated on load.

A folder::

    oracle.json     summary: kind, version, task, phases, eta0 (+ rule, novice model), alpha sweep
                    with solver stats and per-phase envelopes, the paper's hand-set eta0, extras
    arrays.npz      the reference (``ref_*``), the wrench profile of each swept alpha
                    (``alpha_<a>_*``, e.g. ``alpha_0.50_wrench_w``), ``eta0`` and task extras
                    (``extra_*``)
    plots/          wrench_<a>.png (components over time, phases shaded), eta0.png
    reference.mp4   the reference motion rendered with MuJoCo (when rendering was available)
    manifest.json   every other file with its size [bytes] and sha256, and the code revision;
                    written last and checked on load, so a partial or mixed folder never loads

The folder is built beside its target and swapped into place as a whole
(:func:`optimal_control.files.atomic_folder`): a reader sees the old artifact or the new one, and
no file of an earlier artifact (another task's video or solution) stays beside a new one. Writing
over an existing artifact needs ``overwrite=True`` (``--overwrite``).

Readers that must not import solver code (``rl``) read ``oracle.json`` only: ``eta0`` is a list of
per-phase rows ``[fx, fy, fz, mx, my, mz]`` (bounds on force [N] and torque [N m] at the pelvis CoM
per axis of the reference's heading frame, the assist action's frame, see
:mod:`optimal_control.bounds`) in the order of ``phase_names``; the wrench profiles (``wrench_w``)
are world-frame, MuJoCo ``xfrc_applied`` of the pelvis; the warm-start
dataset is ``arrays.npz``: ``ref_q``, ``ref_v``, ``ref_contacts``, ``ref_phase`` and
``wrench_w`` (the novice profile). The artifact is generic in the number and names of phases and
accepts task-specific arrays (``extra_arrays``) and JSON fields (``extra_summary``).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from optimal_control.bounds import (
    AXIS_NAMES,
    PAPER_ETA0,
    BoundRule,
    envelope_per_phase,
    eta0_per_phase,
    help_causes_per_phase,
    wrench_in_heading_frame,
)
from optimal_control.files import (
    atomic_folder,
    atomic_save_npz,
    atomic_write_json,
    git_revision,
    read_npz,
    recover_folder,
)
from optimal_control.reference import Reference
from optimal_control.wrench_profile import WrenchProfile
from robots import g1

ARTIFACT_KIND = "a2cf-mb/oracle"
ARTIFACT_VERSION = 4  # 2: manifest with checksums; 4: soft joint rows (missing_torque_nm)
SUMMARY_FILE = "oracle.json"
MANIFEST_FILE = "manifest.json"
ARRAYS_FILE = "arrays.npz"
VIDEO_FILE = "reference.mp4"
PLOTS_DIR = "plots"


class ArtifactError(ValueError):
    """An oracle artifact folder is missing, malformed or of another version."""


def alpha_key(alpha: float) -> str:
    """Array-key prefix of the profile for ``alpha`` (e.g. ``alpha_0.50_``)."""
    return f"alpha_{alpha:.2f}_"


@dataclass
class OracleArtifact:
    """Everything the oracle computed for one task (see the module docstring for the files)."""

    task: str  # task name ("walk", "dance", "backflip", ...)
    reference: Reference  # the motion the wrenches were computed along
    profiles: dict[float, WrenchProfile]  # alpha -> per-frame QP result
    eta0: np.ndarray  # (num_phases, 6) initial bound [N, N m]
    rule: BoundRule  # how eta0 was derived
    novice_model: str  # name/description of the novice model eta0 reads
    extra_summary: dict = field(default_factory=dict)  # task-specific JSON fields
    extra_arrays: dict[str, np.ndarray] = field(default_factory=dict)  # task-specific arrays
    video: str | None = None  # file name of the video inside the folder, if any
    video_note: str = ""  # why there is no video, if none
    created_utc: str = ""  # creation time (ISO 8601), filled by save
    git_revision: str = ""  # project revision, filled by save

    @property
    def phase_names(self) -> tuple[str, ...]:
        """Names of the phases, one per row of ``eta0``."""
        return self.reference.phase_names

    @property
    def novice_profile(self) -> WrenchProfile:
        """The profile of the rule's novice alpha (the one eta0 was derived from)."""
        return self.profiles[self._alpha_lookup(self.rule.novice_alpha)]

    def _alpha_lookup(self, alpha: float) -> float:
        for key in self.profiles:
            if abs(key - alpha) < 1e-9:
                return key
        raise ArtifactError(
            f"Artifact '{self.task}' has no profile for alpha = {alpha}; swept: "
            f"{sorted(self.profiles)}."
        )

    def eta0_dict(self) -> dict[str, dict[str, list[float]]]:
        """eta0 per phase name as {"force_n": [3], "torque_nm": [3]}."""
        return {
            name: {"force_n": self.eta0[p, :3].tolist(), "torque_nm": self.eta0[p, 3:].tolist()}
            for p, name in enumerate(self.phase_names)
        }

    def validate(self) -> OracleArtifact:
        """Check consistency (phases, shapes, finiteness, novice alpha present); return self."""
        self.reference.validate()
        num_phases = len(self.phase_names)
        t = self.reference.num_frames
        eta0 = np.asarray(self.eta0, dtype=float)
        if eta0.shape != (num_phases, 6):
            raise ArtifactError(
                f"eta0 has shape {eta0.shape}, expected ({num_phases}, 6) for phases "
                f"{self.phase_names}."
            )
        if not np.all(np.isfinite(eta0)) or np.any(eta0 < 0):
            raise ArtifactError(f"eta0 must be finite and >= 0, got {eta0.tolist()}.")
        if not self.profiles:
            raise ArtifactError("An oracle artifact needs at least one wrench profile (alpha).")
        for alpha, prof in self.profiles.items():
            if prof.wrench_w.shape != (t, 6):
                raise ArtifactError(
                    f"Profile alpha={alpha}: wrench_w has shape {prof.wrench_w.shape}, expected "
                    f"({t}, 6) (one row per reference frame)."
                )
            if not np.all(np.isfinite(prof.wrench_w)):
                raise ArtifactError(f"Profile alpha={alpha}: wrench_w has NaN/inf.")
        self._alpha_lookup(self.rule.novice_alpha)
        self.eta0 = eta0
        return self

    def summary(self) -> dict:
        """The JSON summary written to ``oracle.json``."""
        num_phases = len(self.phase_names)
        full = next((a for a in self.profiles if abs(a - 1.0) < 1e-9), None)
        sweep = {}
        for alpha in sorted(self.profiles, reverse=True):
            prof = self.profiles[alpha]
            ok = prof.solved
            env = envelope_per_phase(prof.wrench_w[ok], self.reference.phase[ok], num_phases)
            sweep[f"{alpha:.2f}"] = {
                "solver": prof.stats(),
                "envelope": {k: np.nan_to_num(v).tolist() for k, v in env.items()},
                "unsolved_frames_per_phase": [
                    int(np.sum(~prof.solved[self.reference.phase == p])) for p in range(num_phases)
                ],
                "help_causes_per_phase": (
                    help_causes_per_phase(
                        self.profiles[full].wrench_w,
                        prof.wrench_w,
                        prof.missing_torque_nm,
                        self.reference.phase,
                        self.phase_names,
                        g1.JOINT_NAMES,
                    )
                    if full is not None
                    else None
                ),
                "unaided_fraction_per_phase": [
                    float(prof.unaided[self.reference.phase == p].mean())
                    if np.any(self.reference.phase == p)
                    else None
                    for p in range(num_phases)
                ],
            }
        paper = PAPER_ETA0.get(self.task)
        return {
            "kind": ARTIFACT_KIND,
            "version": ARTIFACT_VERSION,
            "task": self.task,
            "created_utc": self.created_utc,
            "git_revision": self.git_revision,
            "phase_names": list(self.phase_names),
            "axes": list(AXIS_NAMES),
            "wrench_frame": "world-frame force [N] and torque [N m] at the pelvis body CoM "
            "(MuJoCo xfrc_applied of the pelvis)",
            "eta0_frame": "per axis of the reference's heading frame (x forward along the pelvis "
            "yaw, z up): the assist action's frame",
            "eta0": self.eta0.tolist(),
            "eta0_per_phase": self.eta0_dict(),
            "rule": self.rule.to_dict(),
            "novice_model": self.novice_model,
            "help_causes": sweep[f"{self._alpha_lookup(self.rule.novice_alpha):.2f}"][
                "help_causes_per_phase"
            ],
            "alphas": sorted(self.profiles, reverse=True),
            "alpha_sweep": sweep,
            "reference": {
                "name": self.reference.name,
                "frames": self.reference.num_frames,
                "dt_s": self.reference.dt,
                "duration_s": self.reference.duration_s,
                "phase_frames": [int(np.sum(self.reference.phase == p)) for p in range(num_phases)],
                "contact_fraction": self.reference.contacts.mean(axis=0).tolist(),
            },
            "paper_eta0": paper["all"] if paper else None,
            "video": self.video,
            "video_note": self.video_note,
            "files": {"arrays": ARRAYS_FILE, "plots": PLOTS_DIR},
            "extra": self.extra_summary,
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """All arrays written to ``arrays.npz``."""
        out = self.reference.to_arrays("ref_")
        for alpha, prof in self.profiles.items():
            out.update(prof.to_arrays(alpha_key(alpha)))
        out["eta0"] = self.eta0
        out["wrench_w"] = self.novice_profile.wrench_w
        out["alphas"] = np.array(sorted(self.profiles, reverse=True))
        out.update({f"extra_{k}": np.asarray(v) for k, v in self.extra_arrays.items()})
        return out

    def save(
        self,
        folder: str | Path,
        plots: bool = True,
        overwrite: bool = False,
        write_extra: Callable[[OracleArtifact, Path], None] | None = None,
    ) -> Path:
        """Write the artifact to ``folder`` as a whole (atomic folder swap); returns its path.

        Args:
            folder: the artifact folder; it must not exist (or be empty) unless ``overwrite``.
            plots: also write ``plots/``.
            overwrite: replace an existing folder (as a whole: never a mix of old and new files).
            write_extra: called with the artifact and the folder being built, before
                ``oracle.json`` is written, to add task files (a video, a solution); it may set
                fields (e.g. :attr:`video`) that go into the summary.

        Raises:
            OutputExistsError: ``folder`` exists and ``overwrite`` is False.
        """
        self.validate()
        folder = Path(folder)
        self.created_utc = self.created_utc or _dt.datetime.now(_dt.timezone.utc).isoformat()
        revision = git_revision(Path(__file__).resolve().parent)
        if not self.git_revision and revision["commit"]:
            self.git_revision = revision["commit"][:12] + ("-dirty" if revision["dirty"] else "")
        with atomic_folder(folder, overwrite) as tmp:
            if write_extra is not None:
                write_extra(self, tmp)
            atomic_save_npz(tmp / ARRAYS_FILE, self.arrays())
            if plots:
                write_plots(self, tmp / PLOTS_DIR)
            atomic_write_json(tmp / SUMMARY_FILE, self.summary())
            write_manifest(tmp, revision)
        return folder

    @classmethod
    def read_summary(cls, folder: str | Path) -> ArtifactSummary:
        """The light reader: the summary of an artifact folder from ``oracle.json`` alone (its
        manifest checked, no arrays loaded), for readers that need no reference or profiles."""
        folder = Path(folder)
        return ArtifactSummary.from_json(_read_summary_json(folder), folder / SUMMARY_FILE)

    @classmethod
    def load(cls, folder: str | Path) -> OracleArtifact:
        """Read and validate an artifact folder written by :meth:`save`."""
        folder = Path(folder)
        summary = _read_summary_json(folder)
        arrays_path = folder / ARRAYS_FILE
        if not arrays_path.is_file():
            raise ArtifactError(f"'{folder}': {ARRAYS_FILE} is missing.")
        try:
            arrays = read_npz(arrays_path, "artifact arrays")
        except (ValueError, FileNotFoundError) as err:
            raise ArtifactError(str(err)) from err
        try:
            reference = Reference.from_arrays(
                arrays, tuple(summary["phase_names"]), summary["reference"]["name"]
            )
            profiles = {
                float(alpha): _profile_from_arrays(arrays, float(alpha))
                for alpha in summary["alphas"]
            }
        except KeyError as err:
            raise ArtifactError(f"{arrays_path}: array {err} is missing.") from err
        return cls(
            task=summary["task"],
            reference=reference,
            profiles=profiles,
            eta0=np.asarray(summary["eta0"], dtype=float),
            rule=BoundRule.from_dict(summary["rule"]),
            novice_model=summary["novice_model"],
            extra_summary=summary.get("extra", {}),
            extra_arrays={k[6:]: v for k, v in arrays.items() if k.startswith("extra_")},
            video=summary.get("video"),
            video_note=summary.get("video_note", ""),
            created_utc=summary.get("created_utc", ""),
            git_revision=summary.get("git_revision", ""),
        ).validate()


@dataclass(frozen=True)
class ArtifactSummary:
    """What a reader of ``oracle.json`` alone gets (:meth:`OracleArtifact.read_summary`)."""

    task: str  # task name the oracle solved ("walk", "dance", ...)
    phase_names: tuple[str, ...]  # one per row of eta0
    eta0: np.ndarray  # (num_phases, 6) initial bound [N, N m] per heading-frame axis, float64
    eta0_frame: str  # the frame eta0's axes are in, as the artifact states it
    raw: dict  # the whole parsed oracle.json

    @classmethod
    def from_json(cls, summary: dict, path: Path | str = SUMMARY_FILE) -> ArtifactSummary:
        """The summary of a parsed, checked ``oracle.json`` (``path`` names it in errors)."""
        phases = tuple(summary["phase_names"])
        try:
            eta0 = np.asarray(summary["eta0"], dtype=float)
        except (TypeError, ValueError) as err:
            raise ArtifactError(f"{path}: eta0 is not a table of numbers ({err}).") from err
        if eta0.shape != (len(phases), len(AXIS_NAMES)):
            raise ArtifactError(
                f"{path}: eta0 has shape {eta0.shape}, expected ({len(phases)}, "
                f"{len(AXIS_NAMES)}) (one row per phase of {list(phases)}); regenerate the artifact."
            )
        return cls(
            task=summary["task"],
            phase_names=phases,
            eta0=eta0,
            eta0_frame=summary.get("eta0_frame", ""),
            raw=summary,
        )


def _read_summary_json(folder: Path) -> dict:
    """``oracle.json`` of ``folder``, parsed and checked (kind, version, manifest, required
    fields); :class:`ArtifactError` with one line naming what is wrong otherwise."""
    if not folder.exists():
        recover_folder(folder)  # a replacement killed between its two renames
    summary_path = folder / SUMMARY_FILE
    if not summary_path.is_file():
        raise ArtifactError(
            f"'{folder}' is not an oracle artifact: {SUMMARY_FILE} is missing. Create one with "
            "`a2cf-mb solve-walk`, `solve-dance` or `solve-backflip`."
        )
    try:
        summary = json.loads(summary_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ArtifactError(
            f"{summary_path} is not valid JSON ({err}); regenerate the artifact."
        ) from err
    if not isinstance(summary, dict) or summary.get("kind") != ARTIFACT_KIND:
        kind = summary.get("kind") if isinstance(summary, dict) else None
        raise ArtifactError(f"{summary_path}: kind is {kind!r}, not {ARTIFACT_KIND!r}.")
    if summary.get("version") != ARTIFACT_VERSION:
        raise ArtifactError(
            f"{summary_path}: artifact version {summary.get('version')} but this code reads "
            f"version {ARTIFACT_VERSION}; regenerate the artifact."
        )
    verify_manifest(folder)
    for key in ("task", "phase_names", "eta0", "rule", "novice_model", "alphas"):
        if key not in summary:
            raise ArtifactError(f"{summary_path}: required field '{key}' is missing.")
    return summary


def _profile_from_arrays(arrays: dict[str, np.ndarray], alpha: float) -> WrenchProfile:
    p = alpha_key(alpha)
    n = arrays[f"{p}wrench_w"].shape[0]
    return WrenchProfile(
        alpha=alpha,
        wrench_w=arrays[f"{p}wrench_w"],
        contact_wrench_w=arrays[f"{p}contact_wrench_w"],
        corner_forces_w=arrays[f"{p}corner_forces_w"],
        tau_nm=arrays[f"{p}tau_nm"],
        missing_torque_nm=arrays[f"{p}missing_torque_nm"],
        residual=arrays[f"{p}residual"],
        solved=arrays[f"{p}solved"].astype(bool),
        unaided=arrays[f"{p}unaided"].astype(bool),
        iterations=arrays[f"{p}iterations"],
        warm_started=arrays[f"{p}warm_started"].astype(bool),
        solve_time_s=arrays[f"{p}solve_time_s"],
        status=["loaded"] * n,
    )


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_manifest(folder: Path, revision: dict | None = None) -> Path:
    """Write ``manifest.json``: every file under ``folder`` (but itself) with size and sha256.

    ``revision`` is the code revision (:func:`optimal_control.files.git_revision`). Tests that edit
    an artifact on purpose call this again to seal the edit.
    """
    folder = Path(folder)
    files = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel != MANIFEST_FILE:
            files[rel] = {"size_bytes": path.stat().st_size, "sha256": _sha256(path)}
    if revision is None:
        revision = git_revision(Path(__file__).resolve().parent)
    return atomic_write_json(
        folder / MANIFEST_FILE,
        {
            "kind": ARTIFACT_KIND,
            "version": ARTIFACT_VERSION,
            "code_revision": revision,
            "files": files,
        },
    )


def verify_manifest(folder: Path) -> dict:
    """Check that every file the manifest lists is present, of its size and checksum.

    Returns the manifest. Raises :class:`ArtifactError` naming the first file that differs (a
    partial or mixed artifact).
    """
    folder = Path(folder)
    path = folder / MANIFEST_FILE
    regenerate = "the artifact is partial or mixed: regenerate it (solve-* --overwrite)."
    if not path.is_file():
        raise ArtifactError(f"'{folder}': {MANIFEST_FILE} is missing; {regenerate}")
    try:
        manifest = json.loads(path.read_text())
        files = manifest["files"]
        items = [(rel, int(e["size_bytes"]), str(e["sha256"])) for rel, e in files.items()]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as err:
        raise ArtifactError(f"{path} is unreadable ({err}); {regenerate}") from err
    for required in (SUMMARY_FILE, ARRAYS_FILE):
        if required not in files:
            raise ArtifactError(f"{path} does not list {required}; {regenerate}")
    for rel, size, sha in items:
        file = folder / rel
        if not file.is_file():
            raise ArtifactError(f"'{file}' is listed in {MANIFEST_FILE} but missing; {regenerate}")
        if file.stat().st_size != size or _sha256(file) != sha:
            raise ArtifactError(
                f"'{file}' differs from {MANIFEST_FILE} (size or sha256); {regenerate}"
            )
    return manifest


def _shade_phases(ax, time_s: np.ndarray, phase: np.ndarray, colors) -> None:
    starts = np.flatnonzero(np.diff(phase, prepend=-1))
    ends = np.append(starts[1:], len(phase))
    dt = time_s[1] - time_s[0] if len(time_s) > 1 else 1.0
    for s, e in zip(starts, ends, strict=True):
        ax.axvspan(time_s[s], time_s[e - 1] + dt, color=colors[phase[s] % len(colors)], alpha=0.15)


def write_plots(art: OracleArtifact, folder: Path) -> list[Path]:
    """Wrench components over time (phases shaded) per alpha, on the reference's heading axes
    like eta0, and eta0 per phase; returns paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    folder.mkdir(parents=True, exist_ok=True)
    ref = art.reference
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    paths = []
    for alpha in sorted(art.profiles, reverse=True):
        wrench_h = wrench_in_heading_frame(art.profiles[alpha].wrench_w, ref.q[:, 3:7])
        fig, axes = plt.subplots(6, 1, figsize=(10, 11), sharex=True)
        for i, ax in enumerate(axes):
            _shade_phases(ax, ref.time_s, ref.phase, colors)
            ax.plot(ref.time_s, wrench_h[:, i], color="k", lw=1.0)
            p = ref.phase
            ax.plot(ref.time_s, art.eta0[p, i], color="tab:red", lw=0.8, ls="--")
            ax.plot(ref.time_s, -art.eta0[p, i], color="tab:red", lw=0.8, ls="--")
            unit = "N" if i < 3 else "N m"
            ax.set_ylabel(f"{AXIS_NAMES[i]} [{unit}]")
            ax.grid(alpha=0.3)
        axes[-1].set_xlabel("time [s]")
        handles = [
            Patch(color=colors[k % len(colors)], alpha=0.3, label=n)
            for k, n in enumerate(art.phase_names)
        ]
        axes[0].legend(handles=handles, loc="upper right", fontsize=7, ncol=len(handles))
        fig.suptitle(
            f"{art.task}: least pelvis wrench, alpha = {alpha:.2f} (dashed: eta0, rule at "
            f"alpha {art.rule.novice_alpha:.2f})"
        )
        fig.tight_layout()
        path = folder / f"wrench_{alpha:.2f}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    fig, ax = plt.subplots(figsize=(9, 4))
    num = len(art.phase_names)
    paper = PAPER_ETA0.get(art.task, {}).get("all")
    width = 0.8 / (num + (1 if paper else 0))
    x = np.arange(6)
    for p, name in enumerate(art.phase_names):
        ax.bar(x + p * width, art.eta0[p], width, label=f"oracle: {name}")
    if paper:
        rows = np.asarray(paper)
        ax.bar(
            x + num * width, rows.max(axis=0), width, color="0.6", label="paper (max over phases)"
        )
    ax.set_xticks(
        x + 0.4 - width / 2, [f"{a} [{'N' if i < 3 else 'Nm'}]" for i, a in enumerate(AXIS_NAMES)]
    )
    ax.set_ylabel("eta0")
    ax.set_title(f"{art.task}: eta0 per phase ({art.rule.name})")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    path = folder / "eta0.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    paths.append(path)
    return paths


def build_artifact(
    task: str,
    reference: Reference,
    profiles: dict[float, WrenchProfile],
    rule: BoundRule = BoundRule(),
    novice_model: str = "",
    extra_summary: dict | None = None,
    extra_arrays: dict[str, np.ndarray] | None = None,
) -> OracleArtifact:
    """Derive eta0 from the novice profile by ``rule`` (on the reference's heading axes, the
    assist action's) and assemble a validated artifact."""
    art = OracleArtifact(
        task=task,
        reference=reference,
        profiles=profiles,
        eta0=np.zeros((len(reference.phase_names), 6)),
        rule=rule,
        novice_model=novice_model
        or (
            f"per-frame wrench QP along the fixed reference, joint torques limited to "
            f"alpha = {rule.novice_alpha:g} x effort limit, joint accelerations tracked softly "
            "(base rows exact): feasible at every frame"
        ),
        extra_summary=extra_summary or {},
        extra_arrays=extra_arrays or {},
    )
    novice = art.novice_profile
    wrench_h = wrench_in_heading_frame(novice.wrench_w, reference.q[:, 3:7])
    art.eta0 = eta0_per_phase(
        wrench_h, reference.phase, len(reference.phase_names), rule, valid=novice.solved
    )
    return art.validate()
