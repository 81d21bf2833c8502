"""``a2cf-mb play SKILL|BUNDLE``: a learned skill on screen, from its bundle alone.

The zoo (:data:`ZOO_DIR`, installed with the package) holds the best confirmed policy of each
learned skill as a bundle (``policy.onnx``, ``policy.json``, for a tracking policy
``reference.npz``) and ``judge.json``, the figures it was confirmed with. :func:`play` rolls a
bundle out with the standalone runner (:mod:`a2cf_mb.deploy.run_bundle`: MuJoCo, onnxruntime and
numpy, nothing of the training code) and renders robot 0 with the tracking camera: a tracking
policy beside its reference (the ghost), a walk under the scripted commands (forward, backward,
sideways, turn, stop), each frame captioned with its command.

``--viewer`` plays the bundle in MuJoCo's interactive viewer instead, where a display exists, one
episode after another until the window closes; a walk there follows the keyboard
(:class:`KeyboardCommand`).
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ZOO_DIR = Path(__file__).resolve().parent / "zoo"
"""The zoo: one bundle folder per learned skill."""
JUDGE_FILE = "judge.json"
"""A zoo bundle's confirmed figures (what its judge measured, where, from which run)."""


@dataclass(frozen=True)
class PlayConfig:
    """What ``a2cf-mb play`` renders and where."""

    out: str = ""  # video file to write; empty: play/<skill>.mp4 [-]
    seconds: float = 0.0  # episode length played; 0: the bundle's whole episode [s]
    seed: int = 0  # seed of the observation and initial-state noise [-]
    noise: bool = True  # the observation noise the policy was trained with [-]
    viewer: bool = False  # the interactive viewer (a display); a walk: keys [-]

    def __post_init__(self) -> None:
        if not 0.0 <= self.seconds <= 600.0:
            raise ValueError(f"--seconds must be in [0, 600] s, got {self.seconds}")


def zoo_skills() -> list[str]:
    """The skills in the zoo, sorted (folder names under :data:`ZOO_DIR`)."""
    if not ZOO_DIR.is_dir():
        return []
    return sorted(p.name for p in ZOO_DIR.iterdir() if (p / "policy.json").is_file())


def resolve_bundle(target: str | Path) -> Path:
    """A bundle folder from a zoo skill's name or a folder path; one-line ``ValueError`` else."""
    path = Path(target)
    if (path / "policy.json").is_file():
        return path
    if (ZOO_DIR / str(target) / "policy.json").is_file():
        return ZOO_DIR / str(target)
    skills = ", ".join(zoo_skills()) or "none installed"
    raise ValueError(
        f"{target!r} is neither a zoo skill ({skills}) nor a bundle folder (policy.json, "
        "policy.onnx): name a skill or an exported policy's folder"
    )


def walk_script() -> tuple[tuple[float, tuple[float, float, float]], ...]:
    """The walk video's commands: :data:`rl.tasks.walk.evaluation.DEMO_SCRIPT` as
    ((duration [s], (vx, vy, yaw rate)), ...)."""
    from rl.tasks.walk.evaluation import DEMO_SCRIPT

    return tuple((seg.duration_s, seg.command) for seg in DEMO_SCRIPT)


def _reads_velocity_command(bundle: dict[str, Any]) -> bool:
    term = next((t for t in bundle["observation"]["terms"] if t["name"] == "command"), None)
    return term is not None and any(p["name"] == "lin_vel_x" for p in term["parts"])


class ViewerUnavailableError(RuntimeError):
    """No display for MuJoCo's interactive viewer."""


@dataclass
class KeyboardCommand:
    """A walk's velocity command steered from the viewer's keyboard (GLFW key codes): the arrows
    up/down change vx, left/right the yaw rate, comma/period vy (left/right), End stops. Each
    press moves one axis one step, clipped to the walk's training ranges."""

    low: tuple[float, float, float]  # vx [m/s], vy [m/s], yaw rate [rad/s]
    high: tuple[float, float, float]
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))

    KEYS = {
        265: (0, 0.1),  # up: faster forward [m/s]
        264: (0, -0.1),  # down: slower / backward [m/s]
        44: (1, 0.1),  # comma: to the left [m/s]
        46: (1, -0.1),  # period: to the right [m/s]
        263: (2, 0.2),  # left: turn counter-clockwise [rad/s]
        262: (2, -0.2),  # right: turn clockwise [rad/s]
    }
    STOP = 269  # End
    HELP = "arrows: forward/back and turn; comma/period: sideways; End: stop"

    @classmethod
    def for_walk(cls) -> KeyboardCommand:
        """The walk's training ranges (:class:`rl.tasks.walk.command.VelocityCommandConfig`)."""
        from rl.tasks.walk.command import VelocityCommandConfig

        c = VelocityCommandConfig()
        ranges = (c.lin_vel_x_range_mps, c.lin_vel_y_range_mps, c.ang_vel_z_range_rps)
        return cls(low=tuple(r[0] for r in ranges), high=tuple(r[1] for r in ranges))

    def press(self, keycode: int) -> None:
        """Apply one key press (other keys are the viewer's own)."""
        if keycode == self.STOP:
            self.velocity = np.zeros(3)
        elif keycode in self.KEYS:
            axis, step = self.KEYS[keycode]
            velocity = self.velocity.copy()
            velocity[axis] = np.clip(
                round(velocity[axis] + step, 6), self.low[axis], self.high[axis]
            )
            self.velocity = velocity

    def at(self, t_s: float) -> np.ndarray:
        """The command now (whatever the episode time): the runner's ``command_at``."""
        return self.velocity

    def caption(self) -> str:
        vx, vy, wz = self.velocity
        return f"vx {vx:+.1f} m/s  vy {vy:+.1f} m/s  yaw {wz:+.1f} rad/s"


def check_display() -> None:
    """Raise :class:`ViewerUnavailableError` (one line) where no window can open: Linux without
    DISPLAY or WAYLAND_DISPLAY (a server, a container, CI)."""
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise ViewerUnavailableError(
            "play --viewer needs a display (DISPLAY or WAYLAND_DISPLAY is unset); drop --viewer "
            "for a video"
        )


class _ViewerClosed(Exception):
    """The viewer's window was closed: the rollout stops."""


def view(target: str | Path, cfg: PlayConfig = PlayConfig()) -> dict[str, Any]:
    """Play the bundle ``target`` in MuJoCo's interactive viewer, in real time, one episode after
    another (a new seed each) until the window closes; a walk follows :class:`KeyboardCommand`.
    Returns the last episode's figures and how many episodes were played.

    Raises:
        ValueError: ``target`` is no bundle.
        ViewerUnavailableError: no display.
    """
    import mujoco
    import mujoco.viewer

    from a2cf_mb.deploy.run_bundle import build_model, load_bundle, run_bundle

    folder = resolve_bundle(target)
    check_display()
    bundle = load_bundle(folder)
    model = build_model(bundle)
    data = mujoco.MjData(model)
    dt_s = 1.0 / bundle["control"]["policy_rate_hz"]
    keys = KeyboardCommand.for_walk() if _reads_velocity_command(bundle) else None
    num_steps = round(cfg.seconds / dt_s) if cfg.seconds else 0
    result: dict[str, Any] = {}
    episodes = 0
    with mujoco.viewer.launch_passive(
        model, data, key_callback=keys.press if keys else None
    ) as viewer:
        next_frame = time.monotonic()

        def show(q: np.ndarray, reference: np.ndarray | None, velocity: np.ndarray) -> None:
            nonlocal next_frame
            if not viewer.is_running():
                raise _ViewerClosed
            with viewer.lock():
                data.qpos[:] = q
                mujoco.mj_forward(model, data)
                if keys is not None:
                    viewer.set_texts((None, None, keys.caption(), keys.HELP))
            viewer.sync()
            next_frame += dt_s  # real time: the policy's rate
            time.sleep(max(next_frame - time.monotonic(), 0.0))

        while viewer.is_running():
            try:
                result = run_bundle(
                    folder, num_envs=1, num_steps=num_steps, seed=cfg.seed + episodes,
                    noise=cfg.noise, on_step=show, command_at=keys.at if keys else None,
                )  # fmt: skip
            except _ViewerClosed:
                break
            episodes += 1
            next_frame = time.monotonic()
    return {**result, "episodes": episodes}


def play(target: str | Path, cfg: PlayConfig = PlayConfig()) -> dict[str, Any]:
    """Roll the bundle ``target`` (a zoo skill or a folder) out on one robot and write its video;
    returns the runner's figures, the video's path and, for a zoo skill, its judge's figures.

    Raises:
        ValueError: ``target`` is no bundle.
        optimal_control.render.RenderUnavailableError: no offscreen GL context or video writer.
    """
    from a2cf_mb.deploy.run_bundle import load_bundle, run_bundle
    from optimal_control.render import check_offscreen_rendering
    from rl.evaluation.policy import render_qpos

    folder = resolve_bundle(target)
    check_offscreen_rendering()  # before the rollout: a missing GL fails in one line, at once
    bundle = load_bundle(folder)
    name = folder.name
    out = Path(cfg.out) if cfg.out else Path("play") / f"{name}.mp4"
    script = walk_script() if _reads_velocity_command(bundle) else ()
    dt_s = 1.0 / bundle["control"]["policy_rate_hz"]
    num_steps = round(cfg.seconds / dt_s) if cfg.seconds else 0
    if script and not num_steps:
        num_steps = round(sum(d for d, _ in script) / dt_s)
    qpos, ghost, captions = [], [], []

    def record(q: np.ndarray, reference: np.ndarray | None, velocity: np.ndarray) -> None:
        qpos.append(q)
        if reference is not None:
            ghost.append(reference)
        vx, vy, wz = velocity
        captions.append(f"command: vx {vx:+.2f} m/s  vy {vy:+.2f} m/s  yaw {wz:+.2f} rad/s")

    result = run_bundle(
        folder, num_envs=1, num_steps=num_steps, seed=cfg.seed, noise=cfg.noise, script=script,
        on_step=record,
    )  # fmt: skip
    if not qpos:
        raise ValueError(f"{folder}: the robot fell at the first step; nothing to render")
    out.parent.mkdir(parents=True, exist_ok=True)
    video = render_qpos(
        np.stack(qpos), dt_s, str(out), name,
        ghost_qpos=np.stack(ghost) if ghost else None, ghost_side_m=1.0 if ghost else 0.0,
        captions=captions if script else None,
    )  # fmt: skip
    result["video"] = str(video)
    # the sheet's frames spread evenly over the motion, not the time (a flip is half a second)
    moved = np.abs(np.diff(np.stack(qpos), axis=0)).sum(axis=1)
    result["contact_sheet"] = str(contact_sheet(video, video.with_suffix(".png"), moved))
    judge = folder / JUDGE_FILE
    if judge.is_file():
        result["judge"] = json.loads(judge.read_text())
    return result


def contact_sheet(
    video: str | Path, path: str | Path, motion: np.ndarray | None = None, frames: int = 6
) -> Path:
    """A row of ``frames`` frames of ``video`` as one PNG at ``path`` (a picture a README or report
    can show): evenly spaced in time, or, given ``motion`` (T - 1,) (how much the robot moved at
    each step of the T rendered), evenly spaced in the motion done so far."""
    import imageio.v3 as iio

    images = list(iio.imiter(video))
    count = len(images)
    if motion is not None and motion.sum() > 0:
        done = np.concatenate([[0.0], np.cumsum(motion)]) / motion.sum()  # (T,) in [0, 1]
        steps = np.searchsorted(done, np.linspace(0.0, 1.0, frames)).clip(max=len(done) - 1)
        picks = np.round(steps * (count - 1) / max(len(done) - 1, 1)).astype(int)
    else:
        picks = np.round(np.linspace(0, count - 1, frames)).astype(int)
    return write_png(path, np.concatenate([images[i] for i in picks], axis=1))


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write ``image`` (H, W, 3) uint8 as a PNG at ``path``, whole or not at all (atomic)."""
    import imageio.v3 as iio

    from optimal_control.files import atomic_write_bytes

    return atomic_write_bytes(path, iio.imwrite("<bytes>", image, extension=".png"))
