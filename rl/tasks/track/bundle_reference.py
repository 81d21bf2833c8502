"""A tracking policy's reference as its deployment bundle carries it (``reference.npz``): the
motion library of :class:`rl.tasks.track.command.MotionCommand`, every 50 Hz frame as the policy
reads it, held ends included, in MuJoCo conventions, with the text that says how an episode walks
through it (:mod:`rl.agents.bundle` writes it)."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from rl.tasks.track.terms import ANCHOR_BODY, END_EFFECTORS, TRACKED_BODIES


def reference_for_bundle(cmd: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays of a bundle's ``reference.npz`` and the ``reference`` section of its
    ``policy.json`` that describes them (:mod:`rl.agents.bundle`), for the tracking command
    ``cmd`` (:class:`rl.tasks.track.command.MotionCommand`): its whole motion library, every frame
    as the policy reads it."""
    lib = cmd.motion
    clips = lib.clips
    start, length = clips.start.cpu().numpy(), clips.length.cpu().numpy()
    arrays = {
        "qpos": np.asarray(clips.qpos, dtype=np.float64),
        "qvel": np.asarray(clips.qvel, dtype=np.float64),
        "floor_shift_m": np.asarray(clips.floor_shift_m, dtype=np.float64),
        "joint_pos_rad": lib.joint_pos_rad.cpu().numpy(),
        "joint_vel_rps": lib.joint_vel_rps.cpu().numpy(),
        "body_pos_w": lib.body_pos_w.cpu().numpy(),
        "body_quat_w": lib.body_quat_w.cpu().numpy(),
        "body_lin_vel_w": lib.body_lin_vel_w.cpu().numpy(),
        "body_ang_vel_w": lib.body_ang_vel_w.cpu().numpy(),
        "joint_torque_nm": lib.joint_torque_nm.cpu().numpy(),
        "phase": lib.phase.cpu().numpy().astype(np.int64),
        "clip_start": start.astype(np.int64),
        "clip_length": length.astype(np.int64),
    }
    sources = []
    for k, name in enumerate(clips.names):
        rows = arrays["qpos"][start[k] : start[k] + length[k]]
        sources.append(
            {
                "source": name, "start": int(start[k]), "length": int(length[k]),
                "qpos_sha256": hashlib.sha256(rows.tobytes()).hexdigest(),
            }
        )  # fmt: skip
    section = {
        "frames": int(arrays["qpos"].shape[0]),
        "frame_dt_s": float(cmd.cfg.step_dt_s),
        "clips": sources,
        "hold_frames": int(lib.hold_frames),
        "bodies": list(TRACKED_BODIES),
        "anchor_body": ANCHOR_BODY,
        "end_effector_bodies": [TRACKED_BODIES[i] for i in END_EFFECTORS],
        "phase_names": list(lib.phase_names),
        "arrays": {
            "qpos": "(F, 36) MuJoCo qpos of each frame: pelvis position [m], quaternion w x y z, "
            "29 joints [rad]; before the episode's floor shift",
            "qvel": "(F, 35) MuJoCo qvel: pelvis linear velocity (world) [m/s], angular velocity "
            "(pelvis frame) [rad/s], 29 joint rates [rad/s]",
            "floor_shift_m": "(F,) how far frame f is lowered to put its lowest sole corner on the "
            "floor [m]",
            "joint_pos_rad": "(F, 29) joint targets (command joint_pos_ref) [rad]",
            "joint_vel_rps": "(F, 29) joint rates (command joint_vel_ref) [rad/s]",
            "body_pos_w": "(F, K, 3) world positions of `bodies`' link frames, before the floor "
            "shift [m]",
            "body_quat_w": "(F, K, 4) their orientations, w x y z",
            "body_lin_vel_w": "(F, K, 3) their linear velocities, world [m/s]",
            "body_ang_vel_w": "(F, K, 3) their angular velocities, world [rad/s]",
            "joint_torque_nm": "(F, 29) planned joint torques (the feed-forward, zeros for a "
            "clip) [N m]",
            "phase": "(F,) index into phase_names (0 where the references share none)",
            "clip_start": "(C,) first frame of each clip in the arrays",
            "clip_length": "(C,) frames of each clip, held ends included",
        },
        "episode": "episode i tracks clip i mod C from its first frame s = clip_start: the robot "
        "starts at qpos[s], qvel[s], lowered by floor_shift_m[s], and every body_pos_w z of the "
        "episode is lowered by floor_shift_m[s] too. At policy step k (k = 0 first) the command "
        "shows frame n = min(s + k + 1, last): joint_pos_rad[n], joint_vel_rps[n], and the "
        "anchor body's pose at frame n seen from the robot's anchor; the action base is "
        "joint_pos_rad[n] (plus the feed-forward of `control`); after the step the robot is "
        "judged (terminations, errors) against frame n. The episode ends without failing after "
        "the step whose frame n is the clip's last.",
    }
    return arrays, section
