"""Device discipline: code that would fail on a GPU env, found on the CPU.

On a GPU env (``--env-device cuda``) ``t.numpy()`` raises for a tensor on the GPU, but the same
line passes on the CPU, where every test runs. So the sources are read instead: every
``X.numpy()`` in ``rl/``, ``a2cf_mb/`` and the GPU check scripts must take X through ``.cpu()``
(``X.cpu().numpy()``, ``X.detach().cpu().double().numpy()``, ``X.numpy(force=True)``), unless
its code is host-only by design and listed in :data:`HOST_ONLY` with the reason.

Then the evaluation's pieces that a GPU env meets: torch's ``meta`` device stands in for a GPU
(its tensors mix with no CPU tensor), with dummy envs where the physics cannot follow.
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from types import SimpleNamespace

import torch

ROOT = Path(__file__).resolve().parents[1]
SOURCES = (ROOT / "rl", ROOT / "a2cf_mb", ROOT / "docs" / "results" / "gpu")
HOST_ONLY = {
    "rl/evaluation/sim2sim.py": "the second simulator: MuJoCo C on the host, its tensors built there",
    "rl/envs/physics.py": "the MuJoCo C backend, which EnvConfig keeps on the CPU",
    "rl/agents/export.py::check_onnx_against_torch": "host inputs for the exported policy's CPU copy",
}
"""Code allowed ``.numpy()`` without ``.cpu()``: a module path, or ``path::function``, and why."""
MOVES_OFF_THE_HOST = {"to", "cuda"}
"""Methods after a ``.cpu()`` that may put the tensor back on a device."""


def host_copy_misses(source: str) -> list[tuple[int, str]]:
    """``(line, enclosing function)`` of each ``X.numpy()`` in ``source`` whose receiver X is not
    taken through ``.cpu()`` (a chain of method calls ending in ``.cpu()`` and then only methods
    that keep a tensor where it is), nor called with ``force=True``."""
    misses: list[tuple[int, str]] = []

    def on_host(receiver: ast.expr) -> bool:
        while isinstance(receiver, ast.Call) and isinstance(receiver.func, ast.Attribute):
            name = receiver.func.attr
            if name == "cpu":
                return True
            if name in MOVES_OFF_THE_HOST:
                return False
            receiver = receiver.func.value
        return False

    def visit(node: ast.AST, function: str) -> None:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            function = node.name
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "numpy"
            and not any(k.arg == "force" for k in node.keywords)
            and not on_host(node.func.value)
        ):
            misses.append((node.lineno, function))
        for child in ast.iter_child_nodes(node):
            visit(child, function)

    visit(ast.parse(source), "")
    return misses


def source_misses() -> list[tuple[str, int, str]]:
    """``(path, line, function)`` of every miss in the checked sources, allowed ones included."""
    found = []
    for folder in SOURCES:
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for line, function in host_copy_misses(path.read_text()):
                found.append((rel, line, function))
    return found


def allowance(path: str, function: str) -> str | None:
    """The :data:`HOST_ONLY` key that allows a miss in ``function`` of ``path``, if any."""
    for key in (path, f"{path}::{function}"):
        if key in HOST_ONLY:
            return key
    return None


def test_the_lint_tells_host_copies_from_device_tensors() -> None:
    source = """
def f(t, dev):
    t.numpy()
    t.double().numpy()
    t.cpu().to(dev).numpy()
    t.cpu().numpy()
    t.detach().cpu().double().numpy()
    t.numpy(force=True)
"""
    assert host_copy_misses(source) == [(3, "f"), (4, "f"), (5, "f")]


def test_numpy_takes_its_tensor_through_cpu_outside_host_only_code() -> None:
    misses = [(p, line, f) for p, line, f in source_misses() if allowance(p, f) is None]
    where = "\n".join(f"{p}:{line} (in {f or 'the module'})" for p, line, f in misses)
    assert not misses, (
        f".numpy() on a tensor that may be on the env's device (a GPU); write .cpu().numpy(), "
        f"or list host-only code in HOST_ONLY with the reason:\n{where}"
    )


def test_every_host_only_allowance_is_still_used() -> None:
    used = {allowance(p, f) for p, _, f in source_misses()}
    assert set(HOST_ONLY) <= used, f"HOST_ONLY entries no longer needed: {set(HOST_ONLY) - used}"


def test_eval_builds_the_checkpoint_policy_on_the_envs_device(tmp_path) -> None:
    """On a GPU env the policy must live on the GPU; torch's meta device stands in for one (its
    parameters are placeholders there, and the checkpoint's values are not copied: only the
    device is checked)."""
    import warnings

    from test_training import tiny_config

    from rl.envs.vec_env import G1VecEnv
    from rl.evaluation.policy import checkpoint_motion_policy
    from rl.runs.folder import CHECKPOINT_DIR, LAST_CHECKPOINT, load_run_config
    from rl.tasks.registry import resolve_task
    from rl.training.runner import train

    run = train(tiny_config(tmp_path, "a2cf", iterations=1), verbose=False).run_dir
    cfg = load_run_config(run)
    env = G1VecEnv(dataclasses.replace(cfg.env, num_envs=2), resolve_task(cfg))
    try:
        env.device = "meta"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # loading into meta copies nothing
            policy = checkpoint_motion_policy(cfg, env, run / CHECKPOINT_DIR / LAST_CHECKPOINT)
        assert {p.device.type for p in policy.parameters()} == {"meta"}
    finally:
        env.close()


def test_the_eval_video_steps_with_actions_on_the_envs_device() -> None:
    """The video's extra steps move the policy's actions (host ones from the ONNX policy) and the
    zero assist to the env's device (meta, standing in for a GPU; a dummy env)."""
    from rl.evaluation.policy import _extend_video

    class DummyEnv:
        """Records the actions it is stepped with."""

        num_envs, num_actions, device = 2, 35, "meta"

        def __init__(self) -> None:
            self.actions: list[torch.Tensor] = []

        def get_observations(self) -> dict:
            return {"policy": torch.zeros(2, 3)}

        def step(self, actions: torch.Tensor) -> tuple:
            self.actions.append(actions)
            return self.get_observations(), None, None, None

    class Frames(list):
        """A video that counts its frames."""

        def record(self, env) -> None:
            self.append(env)

    env = DummyEnv()
    _extend_video(env, lambda obs: torch.zeros(2, 29), Frames(), 3)
    assert [(a.device.type, tuple(a.shape)) for a in env.actions] == [("meta", (2, 35))] * 3


def test_the_walk_evaluator_copies_only_the_fields_it_scores() -> None:
    """A dummy env whose state holds only what the walk evaluation reads (velocities, command,
    position): it scores the step from them, without copying the whole state to the host."""
    from rl.tasks.walk.evaluation import WalkEvaluationConfig

    n = 2
    start_xy_w = torch.tensor([[1.0, 2.0], [0.0, 0.0]])
    state = SimpleNamespace(base_pos_w=torch.cat([start_xy_w, torch.ones(n, 1)], dim=-1))
    env = SimpleNamespace(
        num_envs=n, device="cpu", skill=None, env_state=state, reset_envs=lambda ids: None
    )
    evaluator = WalkEvaluationConfig().build(env)
    state.base_lin_vel_b = torch.tensor([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0]])
    state.base_ang_vel_b = torch.tensor([[0.0, 0.0, 0.2], [0.0, 0.0, 0.0]])
    state.command = torch.tensor([[1.0, 0.0, 0.0], [0.5, 0.0, 0.3]])
    state.base_pos_w = torch.tensor([[4.0, 6.0, 0.8], [0.3, 0.4, 0.8]])
    dones = torch.zeros(n, dtype=torch.bool)
    extras = {"time_outs": torch.zeros(n, dtype=torch.bool)}
    evaluator.on_step(env, torch.ones(n, dtype=torch.bool), dones, extras)
    torch.testing.assert_close(evaluator.lin_error_sum, torch.tensor([0.0, 0.5]))
    torch.testing.assert_close(evaluator.yaw_error_sum, torch.tensor([0.2, 0.3]))
    torch.testing.assert_close(evaluator.distance_m, torch.tensor([5.0, 0.5]))
