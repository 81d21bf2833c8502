"""Export of the deployable motion policy (normaliser + history encoder + motion head) to ONNX,
with the deployment bundle a robot-side script needs.

The assist head is left out: at deployment no assistive force exists. The ONNX graph takes
``obs`` (B, P) and ``history`` (B, H * P) (the env's "policy" and "history" groups) and returns
``actions`` (B, 29). ``policy.json`` beside it (:func:`deployment_bundle`) says everything a
deployment script needs without reading this code: joint order with default pose, action scale,
PD gains, effort and position limits; the observation layout term by term (name, columns, unit,
how to compute it, the noise trained with; the task command block by block, from the task's
command generator), the history length and order; the control rate; the physics model, the
episode's start and end, and a tracking policy's reference (``reference.npz`` beside it), as
:mod:`rl.agents.bundle` writes them. ``a2cf_mb/deploy/run_bundle.py`` plays a bundle from these
files alone. Every export is checked against torch with onnxruntime; a test rebuilds the
observation from the bundle alone and compares it with the env's.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rl.agents.bundle import episode_facts, model_facts, write_bundle_json, write_reference
from rl.agents.models import A2CFActor, MotionPolicy
from rl.runs.folder import (
    POLICY_BUNDLE_FILE,
    REEXPORT_ADVICE,
    DamagedRunFileError,
    short_reason,
)

ONNX_OPSET = 18
"""ONNX opset used for the export (rsl-rl's choice)."""


BUNDLE_FORMAT = "a2cf-mb-policy/3"
"""Version of ``policy.json``'s layout (3: the model, episode and reference facts of
:mod:`rl.agents.bundle`)."""

OBSERVATION_TERM_DOCS: dict[str, tuple[str, str]] = {
    "base_ang_vel": (
        "rad/s",
        "pelvis angular velocity in the pelvis frame (IMU gyro on the pelvis)",
    ),
    "projected_gravity": ("-", "unit gravity direction (0, 0, -1) in the pelvis frame: R_wb^T g"),
    "joint_pos": ("rad", "joint angles minus default_pos_rad, in the joint order below"),
    "joint_vel": ("rad/s", "joint velocities, in the joint order below"),
    "last_action": ("-", "the policy's previous output `actions` (zeros at start)"),
    "base_lin_vel": (
        "m/s",
        "pelvis linear velocity in the pelvis frame (a state estimator's output; trained with "
        "uniform noise of the term's half-width)",
    ),
    "command": (
        "see parts",
        "the task command: `parts` says what each block of its columns holds and how to produce "
        "it; absent when its width is 0",
    ),
}
"""How a robot computes each policy-observation term (the names of the tasks' policy groups)."""


def reference_joint_columns(command_gen: Any) -> list[int]:
    """Columns [a, b) of the command (not of the observation) that hold the reference joints the
    actions are relative to (``joint_pos_ref``, 29 wide)."""
    col = 0
    for block in command_gen.columns():
        if block.name == "joint_pos_ref" and block.width == 29:
            return [col, col + block.width]
        col += block.width
    raise ValueError(
        f"{type(command_gen).__name__}.columns() has no 29-wide joint_pos_ref block, which "
        "actions_around_reference needs in the bundle"
    )


def command_parts(command_gen: Any, first_column: int, width: int) -> list[dict[str, Any]]:
    """The bundle's ``parts`` of the command term at columns ``first_column`` + [0, ``width``):
    the command generator's blocks (:meth:`rl.envs.components.Command.columns`) with their
    columns, or one block saying that the generator describes none."""
    blocks = command_gen.columns()
    if not blocks:
        return [
            {
                "name": "command", "columns": [first_column, first_column + width], "unit": "?",
                "compute": f"not described by the task's command generator "
                f"({type(command_gen).__name__} has no columns())",
            }
        ]  # fmt: skip
    if sum(b.width for b in blocks) != width:
        raise ValueError(
            f"{type(command_gen).__name__}.columns() describes "
            f"{sum(b.width for b in blocks)} columns, the command has {width}: fix its columns()"
        )
    parts, col = [], first_column
    for block in blocks:
        parts.append(
            {
                "name": block.name, "columns": [col, col + block.width], "unit": block.unit,
                "compute": block.compute, "from_robot": block.from_robot,
            }
        )  # fmt: skip
        col += block.width
    return parts


def deployment_bundle(env: Any) -> dict[str, Any]:
    """The robot-side description of ``env``'s policy interface (see the module docstring)."""
    from robots import g1

    layout = env.observation_layout()["policy"]
    terms = {t.name: t for t in env.task.observations.policy.terms}
    obs_terms = []
    for name, start, width in layout:
        if width == 0:
            continue
        unit, how = OBSERVATION_TERM_DOCS.get(name, ("?", terms[name].func.__doc__ or ""))
        entry = {
            "name": name, "columns": [start, start + width], "unit": unit, "compute": how,
            "scale": terms[name].scale, "training_noise": terms[name].noise,
        }  # fmt: skip
        if name == "command":
            entry["parts"] = command_parts(env.command_gen, start, width)
        obs_terms.append(entry)
    limits = env.layout.joint_range_rad
    base, base_columns, feedforward = "default_pos_rad", {}, ""
    if env.task.actions_around_reference:
        base = "command[action_base_command_columns]"
        base_columns = {"action_base_command_columns": reference_joint_columns(env.command_gen)}
    if env.task.action_feedforward:
        a, b = reference_joint_columns(env.command_gen)
        feedforward = (
            " + kd[i] / kp[i] * command[action_feedforward.joint_vel_command_columns][i]"
            " + action_feedforward.joint_torque_nm[frame][i] / kp[i]"
        )
        base_columns["action_feedforward"] = {
            "joint_vel_command_columns": [b, b + (b - a)],
            "joint_torque_nm": env.command_gen.motion.joint_torque_nm.tolist(),
            "frame": "the reference frame the command's joint_pos_ref block shows (its next "
            "frame), over the references one after another, each with its held ends",
        }
    return {
        "format": BUNDLE_FORMAT,
        "task": env.task.name,
        "control": {
            "policy_rate_hz": 1.0 / env.step_dt_s,
            "physics_dt_s": env.physics_dt_s,
            "decimation": env.cfg.decimation,
            "joint_target": f"target_rad[i] = {base}[i]{feedforward} + action_scale_rad[i] * "
            "actions[i], tracked by a PD law tau = kp (target - q) - kd qdot clipped to "
            "+-effort_limit_nm",
            **base_columns,
        },
        "joints": [
            {
                "name": joint.name,
                "default_pos_rad": float(g1.STAND_JOINT_POS_RAD[i]),
                "action_scale_rad": float(g1.ACTION_SCALE_RAD[i]),
                "kp": float(g1.KP[i]),
                "kd": float(g1.KD[i]),
                "effort_limit_nm": float(g1.EFFORT_LIMIT_NM[i]),
                "position_limits_rad": [float(limits[i, 0]), float(limits[i, 1])],
            }
            for i, joint in enumerate(g1.JOINTS)
        ],  # fmt: skip
        "observation": {
            "width": layout[-1][1] + layout[-1][2],
            "terms": obs_terms,
            "noisy": bool(env.task.observations.policy.noisy and env.cfg.noise),
            "history_length": env.cfg.history_length,
            "history": "input `history` = the last history_length observations (this step's "
            "last), concatenated oldest first; at start every slot holds the first observation",
        },
        "clip_actions": env.cfg.clip_actions,
        "model": model_facts(env),
        "episode": episode_facts(env),
    }


def export_motion_policy(
    actor: A2CFActor,
    path: str | Path,
    check_samples: int = 64,
    tolerance: float = 1e-4,
    env: Any = None,
) -> dict[str, Any]:
    """Write ``actor``'s motion policy to ``path`` (ONNX) and check it against torch.

    Args:
        actor: the trained actor.
        path: output ``.onnx`` file; a ``.json`` description is written beside it.
        check_samples: random input rows for the onnxruntime-vs-torch check.
        tolerance: largest accepted absolute action difference.

    Returns:
        A description: file paths, input/output sizes, ``max_abs_error`` of the check.

    Raises:
        RuntimeError: when onnxruntime's actions differ from torch's by more than ``tolerance``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    policy = actor.motion_policy().cpu().eval()
    dummy = policy.get_dummy_inputs()
    with warnings.catch_warnings():  # the TorchScript exporter is deprecated, still exact here
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            policy,
            dummy,
            str(path),
            export_params=True,
            opset_version=ONNX_OPSET,
            input_names=MotionPolicy.input_names,
            output_names=MotionPolicy.output_names,
            dynamic_axes={"obs": {0: "batch"}, "history": {0: "batch"}, "actions": {0: "batch"}},
            dynamo=False,
        )
    max_err = check_onnx_against_torch(policy, path, check_samples)
    if max_err > tolerance:
        raise RuntimeError(
            f"ONNX export {path} differs from torch by {max_err:.3g} > {tolerance:.3g}"
        )
    description = {
        "onnx": path.name,  # beside this file
        "inputs": {
            "obs": [policy.policy_obs_dim],
            "history": [policy.history_length * policy.policy_obs_dim],
        },
        "outputs": {"actions": [actor.num_motion_actions]},
        "max_abs_error": max_err,
        **(deployment_bundle(env) if env is not None else {}),
    }
    reference = write_reference(path.parent, env) if env is not None else None
    if reference is not None:
        description["reference"] = reference
    write_bundle_json(path.with_suffix(".json"), description)
    return description


KEPT_ON_REFRESH = ("onnx", "inputs", "outputs", "max_abs_error")
"""The keys of ``policy.json`` that describe the ONNX file: :func:`refresh_bundle` keeps them."""


def refresh_bundle(folder: str | Path, env: Any) -> dict[str, Any]:
    """Rewrite ``folder``'s ``policy.json`` with today's deployment facts of ``env`` (an env of
    the task the policy was trained on) and write its reference, keeping the ONNX file and its
    description: a bundle exported before format 3 (no model, episode or reference facts) made
    whole without its checkpoint. Refuses an ``env`` whose policy interface differs from the
    bundle's (observation terms and columns, history, command blocks, action base, feed-forward
    table), which would describe another policy. Returns the new ``policy.json``."""
    path = Path(folder) / POLICY_BUNDLE_FILE
    old = json.loads(path.read_text())
    new = deployment_bundle(env)
    for dotted in ("observation.width", "observation.history_length", "control.policy_rate_hz",
                   "control.action_base_command_columns"):  # fmt: skip
        a, b = (_dotted(d, dotted) for d in (old, new))
        if a != b:
            raise ValueError(f"{path}: {dotted} is {a}, the env's is {b}: not this policy's task")
    strip = ("name", "columns", "parts")
    terms = [[{k: t.get(k) for k in strip} for t in d["observation"]["terms"]] for d in (old, new)]
    for entries in terms:
        for t in entries:
            t["parts"] = [(p["name"], p["columns"]) for p in t["parts"] or []]
    if terms[0] != terms[1]:
        raise ValueError(f"{path}: the observation terms differ from the env's: not this policy")
    old_ff = _dotted(old, "control.action_feedforward.joint_torque_nm")
    new_ff = _dotted(new, "control.action_feedforward.joint_torque_nm")
    if (old_ff is None) != (new_ff is None) or (
        old_ff is not None
        and (
            np.shape(old_ff) != np.shape(new_ff) or np.abs(np.subtract(old_ff, new_ff)).max() > 1e-3
        )
    ):
        raise ValueError(
            f"{path}: the feed-forward torque table differs from the env's reference's: the "
            "reference is not the one the policy was trained on"
        )
    description = {k: old[k] for k in KEPT_ON_REFRESH if k in old} | new
    reference = write_reference(path.parent, env)
    if reference is not None:
        description["reference"] = reference
    write_bundle_json(path, description)
    return description


def _dotted(tree: dict[str, Any], dotted: str) -> Any:
    """``tree["a"]["b"]`` for ``"a.b"``; None where a key is missing."""
    for key in dotted.split("."):
        if not isinstance(tree, dict) or key not in tree:
            return None
        tree = tree[key]
    return tree


def check_onnx_against_torch(
    policy: MotionPolicy, path: str | Path, num_samples: int = 64
) -> float:
    """Largest absolute difference between onnxruntime and torch actions on random inputs."""
    import onnxruntime as ort

    generator = torch.Generator().manual_seed(0)
    obs = torch.randn(num_samples, policy.policy_obs_dim, generator=generator)
    history = torch.randn(
        num_samples, policy.history_length * policy.policy_obs_dim, generator=generator
    )
    with torch.no_grad():
        expected = policy(obs, history).numpy()
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (actual,) = session.run(None, {"obs": obs.numpy(), "history": history.numpy()})
    return float(np.max(np.abs(actual - expected)))


class OnnxMotionPolicy:
    """Runs an exported ``policy.onnx`` with onnxruntime: ``(obs, history) -> actions`` (numpy)."""

    def __init__(self, path: str | Path) -> None:
        """Load the ONNX file."""
        import onnxruntime as ort

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(
                f"exported policy {path} not found: train with --export-onnx first"
            )
        try:
            self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime's own types (InvalidProtobuf, Fail, ...)
            raise DamagedRunFileError(
                f"exported policy {path} cannot be loaded ({short_reason(err)}): "
                f"{REEXPORT_ADVICE.format(run_dir=path.parent)}"
            ) from err

    def __call__(self, obs: np.ndarray, history: np.ndarray) -> np.ndarray:
        """Deterministic motion actions (B, 29) for float32 inputs (B, P) and (B, H * P)."""
        (actions,) = self.session.run(
            None, {"obs": np.asarray(obs, np.float32), "history": np.asarray(history, np.float32)}
        )
        return actions
