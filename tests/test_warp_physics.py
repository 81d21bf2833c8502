"""The MuJoCo Warp backend (``EnvConfig.backend="warp"``) against MuJoCo C, on Warp's CPU device.

Tolerances: Warp integrates in float32 (eps 1.2e-7), MuJoCo C in float64. Started from the same
(float32-representable) state, the stand and dance envs measured max |dqpos| ~1e-6 and
|dqvel| ~1e-4 over 10 policy steps (40 physics steps with 8 sole contacts solved by Newton each
step); the bounds below are ~10x that. Randomised envs are compared by their per-world model rows
(neither backend recomputes the derived fields after a payload: no ``mj_setConst``/``set_const``).
Graph replay against eager launches, and the host reads and eager launches of a step, are
``tests/test_warp_budget.py``'s.

The slow tests need the ``gpu`` extra (mujoco-warp) and compile Warp kernels once (~40 s+, cached
under ~/.cache/warp). Run with ``CUDA_VISIBLE_DEVICES=""`` where no GPU is meant to be used;
``A2CF_WARP_DEVICE=cuda`` runs the same checks on a GPU (``docs/results/gpu/run_gpu_check.sh``):
the Warp env's tensors then live on the GPU and the MuJoCo C env's on the host, so comparisons
between them are made on host copies (:func:`assert_close_on_host`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import importlib.util
import os
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from test_env import misplaced_tensors
from test_training import tiny_config

from a2cf_mb.config_cli import add_config_arguments
from rl.envs.config import EnvConfig
from rl.envs.task_schema import quiet
from rl.envs.vec_env import G1VecEnv
from rl.tasks.dance.task import DANCE_JOINTS as DANCE
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND
from rl.training.runner import train

needs_warp = pytest.mark.skipif(
    importlib.util.find_spec("mujoco_warp") is None,
    reason="mujoco-warp is not installed (pip install -e '.[gpu]')",
)
WARP_DEVICE = os.environ.get("A2CF_WARP_DEVICE", "cpu")
"""Warp device of the slow tests (cpu here; cuda on a GPU machine)."""
QPOS_ATOL = 1e-5  # [m, rad]
QVEL_ATOL = 1e-3  # [m/s, rad/s]
TASKS = {"stand": STAND, "dance": DANCE}


def pair(task, num_envs: int) -> tuple[G1VecEnv, G1VecEnv]:
    """The same quiet task on MuJoCo C and on Warp-CPU, both at Warp's (float32) start state."""
    warp = make_env(quiet(task), num_envs, backend="warp", device=WARP_DEVICE)
    c = make_env(quiet(task), num_envs, num_threads=1)
    align(c, warp)
    return c, warp


def align(c: G1VecEnv, warp: G1VecEnv) -> None:
    """Write the Warp env's state into the MuJoCo C env."""
    lay = c.layout
    c.state[:, lay.qpos] = warp.physics.qpos.double().cpu().numpy()
    c.state[:, lay.qvel] = warp.physics.qvel.double().cpu().numpy()


def assert_close_on_host(actual: torch.Tensor, expected: torch.Tensor, **tolerances) -> None:
    """``torch.testing.assert_close`` of host copies: the Warp env's tensors may be on a GPU."""
    torch.testing.assert_close(actual.cpu(), expected.cpu(), **tolerances)


def max_errors(c: G1VecEnv, warp: G1VecEnv) -> tuple[float, float]:
    """Max |qpos| and |qvel| differences between the backends."""
    dq = (c.physics.qpos - warp.physics.qpos.double().cpu()).abs().max()
    dv = (c.physics.qvel - warp.physics.qvel.double().cpu()).abs().max()
    return float(dq), float(dv)


@pytest.mark.slow
@needs_warp
@pytest.mark.parametrize("task", ["stand", "dance"])
def test_same_states_and_actions_give_the_same_trajectory(task: str) -> None:
    c, warp = pair(TASKS[task], 3)
    gen = torch.Generator().manual_seed(7)
    try:
        for _ in range(10):
            actions = 0.3 * torch.randn(3, 35, generator=gen)
            obs_c, rew_c, done_c, _ = c.step(actions)
            obs_w, rew_w, done_w, _ = warp.step(actions)
            dq, dv = max_errors(c, warp)
            assert dq < QPOS_ATOL and dv < QVEL_ATOL, (dq, dv)
            assert_close_on_host(rew_w, rew_c, rtol=1e-4, atol=1e-4)
            assert torch.equal(done_w.cpu(), done_c.cpu())
            assert_close_on_host(warp.applied_wrench, c.applied_wrench, rtol=1e-4, atol=1e-4)
            sc, sw = c.env_state, warp.env_state
            # sole forces carry the solver's float32 error times the stiffness: ~0.1% of weight
            assert_close_on_host(
                sw.foot_contact_force_n, sc.foot_contact_force_n, rtol=1e-3, atol=0.5
            )
            assert_close_on_host(sw.joint_torque_nm, sc.joint_torque_nm, rtol=1e-3, atol=1e-2)
            assert_close_on_host(obs_w["policy"], obs_c["policy"], rtol=1e-3, atol=1e-3)
        assert warp.diverged_total == c.diverged_total == 0
    finally:
        c.close()
        warp.close()


@pytest.mark.slow
@needs_warp
def test_the_pelvis_wrench_gives_the_same_base_acceleration() -> None:
    """World 0 gets a wrench, world 1 (same state) none: the change of base velocity it causes
    agrees between the backends and points along the force."""
    c, warp = pair(STAND, 2)
    try:
        for env in (c, warp):
            env.physics.qpos[1] = env.physics.qpos[0]
            env.physics.qvel[1] = env.physics.qvel[0]
        wrench_w = torch.tensor([[60.0, -40.0, 80.0, 6.0, 4.0, -5.0], [0.0] * 6])
        dv = {}
        for name, env in (("c", c), ("warp", warp)):  # set_controls takes the env's device's
            targets = env.motion.stand_rad.expand(2, -1)
            env.physics.set_controls(targets, wrench_w.to(env.device))
            env.physics.step()
            qvel = env.physics.qvel.double().cpu()
            dv[name] = (qvel[0, :6] - qvel[1, :6]) / env.step_dt_s  # [m/s^2, rad/s^2]
        torch.testing.assert_close(dv["warp"], dv["c"], rtol=1e-3, atol=1e-2)
        assert dv["c"][0] > 0.5 and dv["c"][1] < -0.3  # along +x and -y, as pushed
    finally:
        c.close()
        warp.close()


@pytest.mark.slow
@needs_warp
def test_a_reset_world_matches_and_the_others_keep_going() -> None:
    c, warp = pair(STAND, 3)
    try:
        for env in (c, warp):
            env.physics.qpos[1, 2] = 0.2  # pelvis on the floor: a fall, hence a reset
        zeros = torch.zeros(3, 35)
        _, _, done_c, _ = c.step(zeros)
        _, _, done_w, _ = warp.step(zeros)
        assert done_c.tolist() == done_w.tolist() == [False, True, False]
        # the reset world starts from the same draw (float32-rounded on Warp)
        assert_close_on_host(warp.physics.qpos[1].double(), c.physics.qpos[1], atol=1e-6, rtol=0)
        assert_close_on_host(warp.physics.qvel[1].double(), c.physics.qvel[1], atol=1e-6, rtol=0)
        assert int(warp.episode_length_buf[1]) == int(c.episode_length_buf[1]) == 0
        assert_close_on_host(
            warp.env_state.foot_contact_force_n,
            c.env_state.foot_contact_force_n,
            rtol=1e-3,
            atol=0.5,
        )
        for _ in range(3):
            c.step(zeros)
            warp.step(zeros)
        dq, dv = max_errors(c, warp)
        assert dq < QPOS_ATOL and dv < QVEL_ATOL, (dq, dv)
    finally:
        c.close()
        warp.close()


@pytest.mark.slow
@needs_warp
def test_broken_worlds_are_counted_and_reset() -> None:
    env = make_env(quiet(STAND), 4, backend="warp", device=WARP_DEVICE)
    try:
        env.physics.qvel[1, 8] = float("nan")
        env.physics.qvel[2, 2] = 1e6  # blows up inside the physics step
        _, reward, dones, extras = env.step(torch.zeros(4, 35))
        assert dones.tolist() == [False, True, True, False]
        assert env.diverged_total == 2 and extras["log"]["Episode/diverged_envs"] == 2.0
        assert reward[1] == reward[2] == 0.0 and torch.isfinite(reward).all()
        assert torch.isfinite(env.physics.qpos).all() and torch.isfinite(env.physics.qvel).all()
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_a_contact_pool_overflow_is_an_error_naming_the_sizes() -> None:
    """A pool of 2 contacts per world cannot hold two standing G1s' 8 sole contacts each: the step
    raises, naming the pool and what to raise, instead of resetting every world."""
    from rl.envs.warp_physics import ContactPoolOverflowError, WarpPhysics

    env = make_env(quiet(STAND), 2, backend="warp", device=WARP_DEVICE)
    try:
        cfg = env.cfg
        tiny = WarpPhysics(env.model, env.randomizer.models, cfg.decimation, cfg.max_abs_qvel,
                           WARP_DEVICE, nconmax_per_world=2)  # fmt: skip
        tiny.qpos[:], tiny.qvel[:] = env.physics.qpos, env.physics.qvel
        tiny.set_controls(env.motion.stand_rad.expand(2, -1), torch.zeros(2, 6, device=env.device))
        tiny.step()  # records the overflow on the device; the env raises after its host read
        flags = {k: float(v) for k, v in tiny.fault_flags().items()}
        assert flags["pool_overflow"] == 1.0 and flags["ncollision"] > 4, flags  # pool: 4
        with pytest.raises(ContactPoolOverflowError) as raised:
            tiny.raise_on_faults(flags)
        message = str(raised.value)
        assert "naconmax = 4 (2 per world x 2 worlds)" in message, message
        assert "--env-warp-nconmax-per-world" in message and "now 2" in message, message
        assert tiny.diverged_total == 0  # raised, not reset
        small = make_env(quiet(STAND), 2, backend="warp", device=WARP_DEVICE,
                         warp_nconmax_per_world=2)  # fmt: skip
        try:  # the env raises in the step itself, from its one host read of the step
            with pytest.raises(ContactPoolOverflowError, match="naconmax = 4"):
                small.step(torch.zeros(2, 35, device=small.device))
        finally:
            small.close()
        sized = make_env(quiet(STAND), 2, backend="warp", device=WARP_DEVICE,
                         warp_nconmax_per_world=64, warp_njmax_per_world=320)  # fmt: skip
        try:  # the env config's flags size the pool
            assert (sized.physics.d.naconmax, sized.physics.d.njmax) == (128, 320)
        finally:
            sized.close()
        tiny.close()
    finally:
        env.close()


def test_cuda_graphs_need_the_memory_pool_and_capture_with_the_gc_paused() -> None:
    """The step is captured only on a CUDA device whose Warp memory pool is on (mjw.step allocates
    inside the capture); the garbage collector is off during the capture and back on after it,
    also when the capture fails."""
    from rl.envs.warp_physics import capture_graph, cuda_graphs_usable

    class Capture:
        """Stands in for ``wp.ScopedCapture``: records nothing, yields a graph."""

        def __init__(self, device) -> None:
            self.graph = f"graph on {device}"

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            return None

    def fake_warp(pool_on: bool) -> SimpleNamespace:
        return SimpleNamespace(
            is_mempool_enabled=lambda device: pool_on,
            ScopedDevice=lambda device: contextlib.nullcontext(),
            ScopedCapture=Capture,
        )

    cuda, cpu = SimpleNamespace(is_cuda=True), SimpleNamespace(is_cuda=False)
    assert cuda_graphs_usable(fake_warp(True), cuda)
    assert not cuda_graphs_usable(fake_warp(False), cuda)
    assert not cuda_graphs_usable(fake_warp(True), cpu)
    seen = []
    graph = capture_graph(fake_warp(True), "cuda:0", lambda: seen.append(gc.isenabled()))
    assert graph == "graph on cuda:0"
    assert seen == [False] and gc.isenabled()  # paused during the capture only

    def fails() -> None:
        raise RuntimeError("capture failed")

    with pytest.raises(RuntimeError, match="capture failed"):
        capture_graph(fake_warp(True), "cuda:0", fails)
    assert gc.isenabled()


@pytest.mark.slow
@needs_warp
def test_state_dict_resumes_exactly_and_refuses_a_mujoco_checkpoint() -> None:
    env = make_env(STAND, 2, backend="warp", device=WARP_DEVICE)
    c = make_env(STAND, 2, num_threads=1)
    try:
        gen = torch.Generator().manual_seed(3)
        actions = [0.3 * torch.randn(2, 35, generator=gen) for _ in range(6)]
        for a in actions[:2]:
            env.step(a)
        saved = env.state_dict()
        first = [env.step(a)[1] for a in actions[2:]]
        env.load_state_dict(saved)
        again = [env.step(a)[1] for a in actions[2:]]
        for r1, r2 in zip(first, again, strict=True):
            torch.testing.assert_close(r1, r2, rtol=1e-6, atol=1e-6)
        with pytest.raises(ValueError, match="--env-backend mujoco"):
            env.load_state_dict(c.state_dict())
    finally:
        env.close()
        c.close()


@pytest.mark.slow
@needs_warp
def test_randomised_worlds_carry_their_own_model_and_derived_fields() -> None:
    """Per-world friction, payload mass and CoM are the randomiser's copies; the derived fields
    stay the nominal model's, as on MuJoCo C (whose copies keep the nominal subtree masses: no
    ``mj_setConst`` after a payload), so no ``set_const`` runs at a reset."""
    env = make_env(STAND, 3, backend="warp", device=WARP_DEVICE)
    try:
        env.physics.qpos[0, 2] = 0.2  # force a reset: world 0 draws new parameters
        env.step(torch.zeros(3, 35))
        phys = env.physics
        body = env.randomizer.writer.body
        mass = phys._model_views["body_mass"]
        ipos = phys._model_views["body_ipos"]
        friction = phys._model_views["geom_friction"]
        mass, ipos, friction = mass.cpu(), ipos.cpu(), friction.cpu()
        subtree = torch.as_tensor(phys.m.body_subtreemass.numpy())
        for i, model in enumerate(env.models):
            assert mass[i, body] == pytest.approx(model.body_mass[body], rel=1e-6)
            np.testing.assert_allclose(ipos[i, body].numpy(), model.body_ipos[body], atol=1e-7)
            np.testing.assert_allclose(
                friction[i, :, 0].numpy(), model.geom_friction[:, 0], rtol=1e-6
            )
            assert subtree.shape[0] == 1  # one row for every world: not per world
            assert subtree[0, 0] == pytest.approx(model.body_subtreemass[0], rel=1e-6)
        assert len({float(mass[i, body]) for i in range(3)}) == 3  # three different payloads
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_shared_model_copies_are_copied_in_once_not_at_every_reset(monkeypatch) -> None:
    """With G shared copies (drawn once), world i steps with copy i % G from its first step on,
    and a reset copies no model rows (no host read of the reset ids)."""
    from rl.envs.warp_physics import WarpPhysics

    task = dataclasses.replace(
        STAND, randomization=dataclasses.replace(STAND.randomization, model_groups=2)
    )
    env = make_env(task, 3, backend="warp", device=WARP_DEVICE)
    try:
        copied = []
        original = WarpPhysics._sync_models
        monkeypatch.setattr(
            WarpPhysics,
            "_sync_models",
            lambda self, rows: copied.append(list(rows)) or original(self, rows),
        )
        env.step(torch.zeros(3, 35, device=env.device))
        env.physics.qpos[0, 2] = 0.2  # a fall: world 0 resets
        _, _, dones, _ = env.step(torch.zeros(3, 35, device=env.device))
        assert dones.tolist() == [True, False, False] and copied == []  # copied at init only
        mass = env.physics._model_views["body_mass"].cpu()
        body = env.randomizer.writer.body
        for g, model in enumerate(env.randomizer.model_copies):
            assert mass[g, body] == pytest.approx(model.body_mass[body], rel=1e-6)
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_the_env_reads_and_writes_the_warp_arrays_themselves() -> None:
    """No per-step copies: qpos, qvel, sensors, joint targets and the pelvis wrench the env reads
    and writes are torch views of the worlds' Warp arrays (same memory)."""
    import warp as wp

    env = make_env(STAND, 2, backend="warp", device=WARP_DEVICE)
    try:
        phys, d = env.physics, env.physics.d
        arrays = {"qpos": d.qpos, "qvel": d.qvel, "ctrl": d.ctrl, "sensordata": d.sensordata}
        arrays["xfrc_applied"] = d.xfrc_applied
        views = {"qpos": phys.qpos, "qvel": phys.qvel, **phys._sim}
        for name, array in arrays.items():
            assert views[name].data_ptr() == wp.to_torch(array).data_ptr(), name
        phys.qvel[1, 0] = 0.125  # writing through the view edits the world's array
        assert float(d.qvel.numpy()[1, 0]) == 0.125
        targets = torch.full((2, 29), 0.25, device=env.device)
        wrench = torch.arange(12.0, device=env.device).reshape(2, 6)
        phys.set_controls(targets, wrench)
        np.testing.assert_array_equal(d.ctrl.numpy(), targets.cpu().numpy())
        pelvis = d.xfrc_applied.numpy()[:, env.layout.pelvis_body]
        np.testing.assert_array_equal(pelvis, wrench.cpu().numpy())
        env.step(torch.zeros(2, 35, device=env.device))
        robot = phys.read()  # computed from the arrays after the step
        np.testing.assert_array_equal(robot["base_pos_w"].cpu().numpy(), d.qpos.numpy()[:, :3])
        np.testing.assert_array_equal(
            robot["joint_torque_nm"].cpu().numpy(), d.sensordata.numpy()[:, env.layout.torque]
        )
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_every_tensor_of_the_warp_env_lives_on_its_device() -> None:
    env = make_env(STAND, 2, backend="warp", device=WARP_DEVICE)
    try:
        assert env.device == WARP_DEVICE
        assert env.generator.device.type == torch.device(WARP_DEVICE).type
        for _ in range(2):
            env.step(torch.randn(2, 35, device=env.device))
        assert misplaced_tensors(env) == []
    finally:
        env.close()


@pytest.mark.slow
@needs_warp
def test_two_training_iterations_on_warp_cpu(tmp_path) -> None:
    env = EnvConfig(backend="warp", device=WARP_DEVICE, num_envs=4, num_threads=1)
    cfg = tiny_config(tmp_path, "a2cf", env=env)
    result = train(cfg, verbose=False)
    assert result.iterations_done == 2
    assert (result.run_dir / "policy.onnx").is_file()


def test_missing_mujoco_warp_names_the_extra(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "mujoco_warp", None)  # import fails as if not installed
    with pytest.raises(ModuleNotFoundError, match=r"a2cf-mb\[gpu\]"):
        make_env(quiet(STAND), 1, backend="warp")


def test_the_cli_names_the_missing_extra_in_one_line(monkeypatch, tmp_path, capsys) -> None:
    from a2cf_mb.cli import main as cli_main

    monkeypatch.setitem(sys.modules, "mujoco_warp", None)
    args = ["train", "--task", "stand", "--backend", "warp", "--num-envs", "2", "--iterations",
            "1", "--out", str(tmp_path), "--run-name", "warp"]  # fmt: skip
    assert cli_main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "a2cf-mb[gpu]" in err and "Traceback" not in err
    assert not (tmp_path / "warp").exists()  # nothing half-written


def test_backend_and_device_are_checked_and_have_a_short_flag() -> None:
    with pytest.raises(ValueError, match="mujoco, warp|'mujoco', 'warp'"):
        EnvConfig(backend="bullet")
    with pytest.raises(ValueError, match="--env-backend warp"):
        EnvConfig(device="cuda")
    with pytest.raises(ValueError, match="cuda:N"):
        EnvConfig(backend="warp", device="gpu")
    import argparse

    @dataclasses.dataclass(frozen=True)
    class Holder:
        """A config holding an env config."""

        env: EnvConfig = EnvConfig()

    parser = argparse.ArgumentParser()
    add_config_arguments(parser, Holder)
    args = parser.parse_args(["--backend", "warp", "--env-device", "cuda:0"])
    assert (getattr(args, "env.backend"), getattr(args, "env.device")) == ("warp", "cuda:0")
