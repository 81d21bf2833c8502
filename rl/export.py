"""Export of the deployable motion policy (normaliser + history encoder + motion head) to ONNX.

The assist head is left out: at deployment no assistive force exists. The ONNX graph takes
``obs`` (B, P) and ``history`` (B, H * P) (the env's "policy" and "history" groups, noisy as on the
robot) and returns ``actions`` (B, 29); the joint target is
``robots.g1.STAND_JOINT_POS_RAD + robots.g1.ACTION_SCALE_RAD * actions``. A ``policy.json`` next to
the ``.onnx`` file describes this. Every export is checked against torch with onnxruntime.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rl.agents.models import A2CFActor, MotionPolicy

ONNX_OPSET = 18
"""ONNX opset used for the export (rsl-rl's choice)."""


def export_motion_policy(
    actor: A2CFActor, path: str | Path, check_samples: int = 64, tolerance: float = 1e-4
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
        "onnx": str(path),
        "inputs": {
            "obs": [policy.policy_obs_dim],
            "history": [policy.history_length * policy.policy_obs_dim],
        },
        "outputs": {"actions": [actor.num_motion_actions]},
        "history_length": policy.history_length,
        "joint_target": "robots.g1.STAND_JOINT_POS_RAD + robots.g1.ACTION_SCALE_RAD * actions",
        "max_abs_error": max_err,
    }
    path.with_suffix(".json").write_text(json.dumps(description, indent=2))
    return description


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
        self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])

    def __call__(self, obs: np.ndarray, history: np.ndarray) -> np.ndarray:
        """Deterministic motion actions (B, 29) for float32 inputs (B, P) and (B, H * P)."""
        (actions,) = self.session.run(
            None, {"obs": np.asarray(obs, np.float32), "history": np.asarray(history, np.float32)}
        )
        return actions
